"""What the background stage costs per sample, by background kind, on one core (issue 79).

    python benchmarks/probes/background_stage.py [--n 12] [--rounds 3] [--profile] [--against REV]

For each sky kind (clean, complex, earth, cluttered) it draws n 640x480 specs from scgen's own sampler
(seed 0, the default preset, the kind forced), and times scgen.render.sky.backgrounds.background_image on
each, in a child process on one thread (OMP/BLAS/OpenCV at one thread; the maps and the catalogue loaded
and one image made first), after the sample's lighting (scgen.render.lighting.body_albedo_light), as in a
render: the lighting makes a Blue Marble Earth's cloud map, which the background reuses. Each round runs
every spec once; a spec's time is its fastest of the rounds, and the table prints each kind's median over
its specs and their mean over the four kinds.

--against REV times the code of git revision REV too (a detached worktree, imported by the child through
PYTHONPATH), its child and the working tree's taking turns round by round (A B B A ...), so that a
machine's drift weighs on both alike; then it compares their images spec by spec: the largest absolute
difference and the PSNR with the peak at 1.0 (a white plate under the sun at EV 0: the images are linear
radiance), worst first. --profile adds cProfile's functions by their own time, per kind, for the working
tree's code.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import pstats
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import ONE_THREAD, ROOT, parser, revision_tree, run_script

KINDS = ("clean", "complex", "earth", "cluttered")
RESOLUTION, SEED = (640, 480), 0


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--n", type=int, default=12, help="Specs per kind [12].")
    ap.add_argument("--rounds", type=int, default=3, help="Times each spec is timed; the fastest counts [3].")
    ap.add_argument("--profile", action="store_true", help="Print cProfile's top functions per kind.")
    ap.add_argument("--against", metavar="REV", help="Also time git revision REV and compare the images.")
    ap.add_argument("--child", type=Path, help=argparse.SUPPRESS)  # one round, written to this .npz
    ap.add_argument("--images", action="store_true", help=argparse.SUPPRESS)  # the child keeps its images
    ap.add_argument("--profile-child", action="store_true", help=argparse.SUPPRESS)  # the child profiles
    return ap.parse_args()


def specs(n: int) -> dict[str, list]:
    """n specs per kind, from scgen's sampler."""
    from scgen import Generator

    out = {}
    for kind in KINDS:
        overrides = {"background": {"probs": {k: float(k == kind) for k in (*KINDS, "user")}}}
        gen = Generator.load(seed=SEED, resolution=RESOLUTION, overrides=overrides, backend="mitsuba")
        out[kind] = [gen.scene(i) for i in range(n)]
        assert all(s.background.kind == kind for s in out[kind])
    return out


def child(args: argparse.Namespace) -> None:
    """One round: every spec's time (and image) with the code that PYTHONPATH imports."""
    import cv2

    cv2.setNumThreads(1)
    from scgen.render.lighting import body_albedo_light
    from scgen.render.sky.backgrounds import background_image

    drawn = specs(args.n)
    for kind in KINDS:
        background_image(drawn[kind][0])  # maps, catalogue, caches
    times, images = {}, {}
    for kind in KINDS:
        for i, spec in enumerate(drawn[kind]):
            body_albedo_light(spec)  # as in a render, the lighting first: it makes the Earth's cloud map
            t0 = time.perf_counter()
            img = background_image(spec)
            times[f"{kind}/{i}"] = time.perf_counter() - t0
            if args.images:
                images[f"{kind}/{i}"] = img
    np.savez(
        args.child, times=json.dumps(times), **{f"img_{k.replace('/', '_')}": v for k, v in images.items()}
    )


def one_round(code: Path | None, out: Path, args: argparse.Namespace, images: bool) -> dict:
    env = os.environ | ONE_THREAD | {"PYTHONPATH": str(code or ROOT)}  # this scgen, not an installed one
    cmd = [sys.executable, __file__, "--child", str(out), "--n", str(args.n)] + ["--images"] * images
    subprocess.run(cmd, env=env, check=True, cwd=code or ROOT)
    with np.load(out) as f:
        return {"times": json.loads(str(f["times"])), "images": {k: f[k] for k in f.files if k != "times"}}


def table(label: str, runs: list[dict]) -> dict[str, float]:
    best = {k: min(r["times"][k] for r in runs) for k in runs[0]["times"]}
    per_kind = {
        kind: statistics.median(v for k, v in best.items() if k.startswith(kind + "/")) for kind in KINDS
    }
    print(
        f"{label:10} "
        + " ".join(f"{1e3 * per_kind[k]:10.1f}" for k in KINDS)
        + f" {1e3 * statistics.mean(per_kind.values()):10.1f}"
    )
    return per_kind


def compare(old: dict, new: dict) -> None:
    rows = []
    for key, a in old.items():
        b = new[key]
        diff = np.abs(a.astype(np.float64) - b)
        mse = float(np.mean(diff**2))
        psnr = np.inf if mse == 0 else 10 * np.log10(1.0 / mse)
        rows.append((psnr, float(diff.max()), key[4:]))
    rows.sort()
    print(f"\nimages against the old code, worst first (PSNR dB, peak 1.0; max |diff|), {len(rows)} specs:")
    for psnr, worst, key in rows[:8]:
        print(f"  {key:14} {psnr:8.2f} {worst:.3g}")
    print(f"  worst PSNR {rows[0][0]:.2f} dB, largest |diff| {max(r[1] for r in rows):.3g}, "
          f"identical {sum(r[1] == 0 for r in rows)} of {len(rows)}")  # fmt: skip


def profile(args: argparse.Namespace) -> None:
    import cv2

    cv2.setNumThreads(1)
    from scgen.render.lighting import body_albedo_light
    from scgen.render.sky.backgrounds import background_image

    drawn = specs(args.n)
    for kind in KINDS:
        background_image(drawn[kind][0])
        prof = cProfile.Profile()
        for spec in drawn[kind]:
            body_albedo_light(spec)
            prof.enable()
            background_image(spec)
            prof.disable()
        text = io.StringIO()
        pstats.Stats(prof, stream=text).sort_stats("tottime").print_stats(14)
        print(f"\n== {kind}: cProfile over {args.n} specs, by own time (s)")
        print("\n".join(line for line in text.getvalue().splitlines()[4:] if line.strip()))


def run(args: argparse.Namespace) -> None:
    if args.child:
        child(args)
        return
    if args.profile_child:
        profile(args)
        return
    print(f"load average {os.getloadavg()[0]:.2f}; {RESOLUTION[0]}x{RESOLUTION[1]}, {args.n} specs a kind, "
          f"one thread, fastest of {args.rounds} rounds, median ms")  # fmt: skip
    print(f"{'code':10} " + " ".join(f"{k:>10}" for k in KINDS) + f" {'mean':>10}")
    with tempfile.TemporaryDirectory() as tmp:
        if args.against:
            with revision_tree(args.against) as rev:
                runs: dict[str, list] = {"old": [], "new": []}
                for r in range(args.rounds):
                    order = ("old", "new") if r % 2 == 0 else ("new", "old")
                    for which in order:
                        code = rev / "code" if which == "old" else None
                        runs[which].append(one_round(code, Path(tmp) / f"{which}{r}.npz", args, r == 0))
            table(args.against, runs["old"])
            table("working", runs["new"])
            compare(runs["old"][0]["images"], runs["new"][0]["images"])
        else:
            table(
                "working", [one_round(None, Path(tmp) / f"r{r}.npz", args, False) for r in range(args.rounds)]
            )
    print(f"load average {os.getloadavg()[0]:.2f}")
    if args.profile:  # in a child, on one thread too
        cmd = [sys.executable, __file__, "--profile-child", "--n", str(args.n)]
        subprocess.run(cmd, env=os.environ | ONE_THREAD | {"PYTHONPATH": str(ROOT)}, check=True)


if __name__ == "__main__":
    run_script(run, parse_args())
