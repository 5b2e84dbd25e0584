"""Draw docs/camera_before_after.jpg: the same samples rendered with the code at another revision and
with this tree, side by side, and print the two renders' over-exposure and factor-group tables.

    python benchmarks/figures/camera_before_after.py --before b970dd6 [--seed 7] [--ids 15 75 ...]
        [--resolution 640x480] [--backend mitsuba] [--out docs/camera_before_after.jpg]
        [--tables BEFORE_DIR AFTER_DIR]

Each sample is rendered in memory as `scgen render` writes it (scgen.Generator, default config and
camera), once by a child process importing scgen from a temporary git worktree of REV and once with
this tree. A pair's label gives the sample, its background and the share of its pixel values at the
top code. `--tables` reads two datasets' metadata.csv (renders of one seed with the two codes) and
prints, over the samples both hold, the share of images with more than 1, 5 and 10 % of their pixel
values clipped, and the flare, finish and background groups.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import ROOT, parse_resolution, parser, revision_tree, run_script

# seed 7: the most clipped before (earth, cluttered), the sun near the view, complex skies, nominal finishes
IDS = (1098, 2109, 576, 15, 535, 1820, 75, 180, 347, 386, 2, 4, 6, 3, 31, 74)
PANEL = (320, 240)
COLUMNS = 4
CLIP_SHARES = (0.01, 0.05, 0.10)
GROUPS = ("flare", "finish", "background")


def dump(out: Path, seed: int, ids: list[int], resolution: tuple[int, int], backend: str) -> None:
    """Render `ids` with whichever scgen is importable; write each image and its label facts."""
    from scgen import Generator

    out.mkdir(parents=True, exist_ok=True)
    with Generator.load(seed=seed, resolution=resolution, backend=backend) as gen:
        for i in ids:
            sample = gen.sample(i)
            rgb, record = sample.buffers.rgb, sample.buffers.camera
            cv2.imwrite(str(out / f"{i}.png"), rgb[..., ::-1] if rgb.ndim == 3 else rgb)
            facts = {
                "background": sample.spec.background.kind,
                "flare": record.flare,
                "saturated": record.saturated,
            }
            (out / f"{i}.json").write_text(json.dumps(facts))


def render_with(code: Path, out: Path, args: argparse.Namespace) -> None:
    """This script's `--dump` in a child process whose scgen comes from `code`."""
    size = "x".join(map(str, args.resolution))
    command = [sys.executable, __file__, "--dump", str(out), "--seed", str(args.seed), "--resolution", size,
               "--backend", args.backend, "--ids", *map(str, args.ids)]  # fmt: skip
    subprocess.run(command, env={**os.environ, "PYTHONPATH": str(code)}, cwd=code, check=True)


def panel(folder: Path, i: int, title: str) -> np.ndarray:
    image = cv2.resize(cv2.imread(str(folder / f"{i}.png")), PANEL, interpolation=cv2.INTER_AREA)
    facts = json.loads((folder / f"{i}.json").read_text())
    text = f"{title} #{i} {facts['background']}{' flare' if facts['flare'] else ''}"
    text += f" clipped {100 * facts['saturated']:.1f}%"
    strip = np.full((22, PANEL[0], 3), 30, np.uint8)
    cv2.putText(strip, text, (5, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (235, 235, 235), 1, cv2.LINE_AA)
    return np.vstack([strip, image])


def grid(before: Path, after: Path, ids: list[int], rev: str) -> np.ndarray:
    """Pairs (before | after) in rows of COLUMNS, a gap between pairs."""
    gap = np.full((PANEL[1] + 22, 8, 3), 255, np.uint8)
    pairs = [np.hstack([panel(before, i, rev), panel(after, i, "now"), gap]) for i in ids]
    rows = [np.hstack(pairs[k : k + COLUMNS]) for k in range(0, len(pairs), COLUMNS)]
    return np.vstack([np.vstack([r, np.full((8, r.shape[1], 3), 255, np.uint8)]) for r in rows])


def tables(before: Path, after: Path) -> None:
    """Markdown tables of over-exposure and factor groups over the samples both datasets hold."""
    rows = [
        {int(r["sample_id"]): r for r in csv.DictReader((d / "metadata.csv").open())} for d in (before, after)
    ]
    ids = sorted(rows[0].keys() & rows[1].keys())
    sat = [np.array([float(r[i]["saturated"]) for i in ids]) for r in rows]
    print(f"{len(ids)} samples in both\n")
    print("| images with more than … of their pixel values clipped | before | after |\n|---|---|---|")
    for share in CLIP_SHARES:
        print(f"| {share:.0%} | " + " | ".join(f"{np.mean(s > share):.1%}" for s in sat) + " |")
    print("| worst image | " + " | ".join(f"{s.max():.1%}" for s in sat) + " |\n")
    print("| group | before | after |\n|---|---|---|")
    for factor in GROUPS:
        values = sorted({r[i][factor] for r in rows for i in ids})
        for value in values:
            counts = [sum(r[i][factor] == value for i in ids) for r in rows]
            print(f"| {factor} {value} | {counts[0]} | {counts[1]} |")


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--before", help="git revision of the code before")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--ids", type=int, nargs="+", default=list(IDS))
    ap.add_argument("--resolution", type=parse_resolution, default=(640, 480), help="WxH [640x480]")
    ap.add_argument("--backend", default="mitsuba")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "camera_before_after.jpg")
    ap.add_argument("--tables", type=Path, nargs=2, metavar=("BEFORE_DIR", "AFTER_DIR"))
    ap.add_argument("--dump", type=Path, help=argparse.SUPPRESS)
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    if args.dump:
        dump(args.dump, args.seed, args.ids, args.resolution, args.backend)
        return
    if args.tables:
        tables(*args.tables)
    if not args.before:
        return
    with revision_tree(args.before) as tmp:
        render_with(tmp / "code", tmp / "before", args)
        render_with(ROOT, tmp / "after", args)
        figure = grid(tmp / "before", tmp / "after", args.ids, args.before[:7])
    cv2.imwrite(str(args.out), figure, [cv2.IMWRITE_JPEG_QUALITY, 88])
    print(f"wrote {args.out} ({figure.shape[1]}x{figure.shape[0]})")


if __name__ == "__main__":
    run_script(run, parse_args())
