"""Is a fixed seed's dataset byte-identical with the code at another revision? For changes that must
not move a byte (a reorganisation, a speed-up): renders the same job with the code at REV (a temporary
git worktree on PYTHONPATH) and with this tree, for each backend, and compares every file.

Prints one line per backend (files compared, files that differ) and each differing file; exit status 1
if any file differs.

Usage: python benchmarks/same_output.py --against REV [--backends mitsuba blender] [--n 8] [--seed 21]
       [--resolution 160x120] [--camera speedplus] [--rgb-format png]

--rgb-format passes the format to both renders: against a revision before `--rgb-format auto` (the
default camera's images as JPEG), `--rgb-format png` renders what both write.
"""

from __future__ import annotations

import argparse
import filecmp
import os
import subprocess
import sys
from pathlib import Path

from harness import ROOT, parser, revision_tree, run_script

from scgen.io import usable_cores


def render(
    code: Path,
    out: Path,
    backend: str,
    n: int,
    seed: int,
    resolution: str,
    camera: str | None,
    rgb_format: str | None,
) -> None:
    """`scgen render` of the job with the scgen package found in `code`."""
    env = {**os.environ, "PYTHONPATH": str(code)}
    # a worker per core, as `scgen render` runs by default (and the code before the Mitsuba thread default,
    # 2150d39, ran its workers on one thread each only then)
    options = {"--n": n, "--seed": seed, "--out": out, "--backend": backend, "--resolution": resolution,
               "--quality": "draft", "--workers": usable_cores()}  # fmt: skip
    if camera:
        options["--camera"] = camera
    if rgb_format:
        options["--rgb-format"] = rgb_format
    command = [
        sys.executable,
        "-m",
        "scgen.cli",
        "render",
        "--quiet",
        *(str(v) for kv in options.items() for v in kv),
    ]
    subprocess.run(command, env=env, check=True, cwd=code)


def differing_files(a: Path, b: Path) -> tuple[int, list[str]]:
    """(files compared, relative paths that differ or exist on one side only)."""
    files_a = {p.relative_to(a) for p in a.rglob("*") if p.is_file()}
    files_b = {p.relative_to(b) for p in b.rglob("*") if p.is_file()}
    differ = sorted(str(p) for p in files_a ^ files_b)
    differ += sorted(str(p) for p in files_a & files_b if not filecmp.cmp(a / p, b / p, shallow=False))
    return len(files_a | files_b), differ


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--against", required=True, help="git revision to compare with (e.g. HEAD~1, a tag)")
    ap.add_argument("--backends", nargs="+", default=["mitsuba", "blender"])
    ap.add_argument("--n", type=int, default=8)
    ap.add_argument("--seed", type=int, default=21)
    ap.add_argument("--resolution", default="160x120")
    ap.add_argument("--camera", help="camera preset (e.g. speedplus: through a lens); default: the config's")
    ap.add_argument("--rgb-format", choices=["png", "jpg"], help="image format for both; default: each's own")
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    failed = False
    with revision_tree(args.against) as tmp:
        for backend in args.backends:
            before, after = tmp / f"{backend}_before", tmp / f"{backend}_after"
            job = (backend, args.n, args.seed, args.resolution, args.camera, args.rgb_format)
            render(tmp / "code", before, *job)
            render(ROOT, after, *job)
            count, differ = differing_files(before, after)
            print(f"{backend}: {count} files compared, {len(differ)} differ")
            for path in differ:
                print(f"  differs: {path}")
            failed |= bool(differ)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    run_script(run, parse_args())
