"""Images/s at 1 and 2 worker processes in one run, and the scaling ratio (target >= 0.9x linear).

Two figures per configuration:
- wall: samples / wall time of the whole `run_render` call (planning, process start-up, scene
  build, the last worker's tail), what a short run sees;
- steady: workers / mean per-sample time inside the workers (render + annotate + write), what a
  long run such as 50,000 images converges to; contention between workers (cores, memory
  bandwidth, a shared GPU) slows each sample and so shows up here, start-up does not.

Each configuration runs twice in turn: Blender tracing the full frame (the old path, SCGEN_FULL_FRAME=1)
and only the region the objects cover (the default); `--modes region` skips the old path. With --repeat R
the configurations run R times in turn (1, 2, 3, 1, 2, 3, ...) and each figure is the median, so a drift
in the machine's speed hits every configuration alike. The first two configurations give the scaling
ratio. On a GPU machine, e.g.:
    python benchmarks/bench_workers.py --device gpu --runs 1x16 2x8 4x4 --n 64

Usage: python benchmarks/bench_workers.py [--backend blender] [--n 16] [--quality default]
       [--device auto|cpu|gpu] [--runs WxT ...] [--repeat R] [--modes full region]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

from harness import parser, run_script

from scgen.io import usable_cores
from scgen.render.region import FULL_FRAME_ENV
from scgen.run.runner import RenderJob, run_render

MODES = {"full": "1", "region": ""}  # SCGEN_FULL_FRAME per mode, which the workers inherit


def measure(job: RenderJob, mode: str) -> tuple[float, float]:
    """(wall images/s, steady-state images/s) of one run, in `mode` (a key of MODES)."""
    before = os.environ.get(FULL_FRAME_ENV)
    os.environ[FULL_FRAME_ENV] = MODES[mode]
    t0 = time.perf_counter()
    try:
        summary = run_render(job, progress=False)
    finally:
        if before is None:
            del os.environ[FULL_FRAME_ENV]
        else:
            os.environ[FULL_FRAME_ENV] = before
    wall = job.n / (time.perf_counter() - t0)
    per_sample = (summary["render_s"] + summary["other_s"]) / summary["rendered"]
    return wall, job.workers / per_sample


def parse_run(text: str) -> tuple[int, int]:
    """'2x8' -> (2 workers, 8 renderer threads each)."""
    workers, threads = (int(v) for v in text.lower().split("x"))
    return workers, threads


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--backend", default="blender")
    ap.add_argument("--n", type=int, default=16)
    ap.add_argument("--quality", default="default")
    ap.add_argument("--device", default="auto", choices=["auto", "cpu", "gpu"])
    ap.add_argument("--runs", nargs="+", type=parse_run, default=None, metavar="WxT",
                    help="workers x threads per worker [1x1, {cores}x1, 1x{cores}]")  # fmt: skip
    ap.add_argument("--repeat", type=int, default=1, help="Rounds over all configurations; medians.")
    ap.add_argument("--modes", nargs="+", choices=list(MODES), default=list(MODES), help="[full region]")
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    cores = usable_cores()
    runs = args.runs or [(1, 1), (cores, 1), (1, cores)]
    tmp = Path(tempfile.mkdtemp())
    names = {(w, t, m): f"{w} worker(s) x {t} thread(s), {m}" for w, t in runs for m in args.modes}
    samples: dict[str, list[tuple[float, float]]] = {name: [] for name in names.values()}
    for r in range(args.repeat):
        for (w, t, mode), name in names.items():
            job = RenderJob(
                out=tmp / f"r{r}w{w}t{t}{mode}", n=args.n, seed=0, backend=args.backend, quality=args.quality,
                device=args.device, workers=w, threads=t,
            )  # fmt: skip
            samples[name].append(measure(job, mode))
    rates = {
        name: (statistics.median(v[0] for v in vals), statistics.median(v[1] for v in vals))
        for name, vals in samples.items()
    }
    print(
        f"{args.backend} ({args.quality}, {args.device}, 640x480), {args.n} samples per run, {cores} cores,"
        f" median of {args.repeat}"
    )
    print(f"  {'':<40s} {'wall img/s':>10s} {'steady img/s':>12s} {'wall s/img':>10s}")
    for name, (wall, steady) in rates.items():
        print(f"  {name:<40s} {wall:10.3f} {steady:12.3f} {1 / wall:10.3f}")
    if len(args.modes) == 2:
        for w, t in runs:
            old, new = (rates[names[w, t, m]] for m in ("full", "region"))
            print(f"  {w}x{t}: region / full frame, wall {old[0] / new[0]:.3f}, steady {old[1] / new[1]:.3f}"
                  " of the time per image")  # fmt: skip
    if len(runs) > 1 and runs[0] == (1, 1):
        k = runs[1][0]
        for mode in args.modes:
            one, many = rates[names[(*runs[0], mode)]], rates[names[(*runs[1], mode)]]
            for label, i in (("wall", 0), ("steady", 1)):
                ratio = many[i] / one[i]
                print(
                    f"  {mode} {label:<6s} scaling: {ratio:.2f}x with {k} workers = {ratio / k:.2f} of linear"
                )


if __name__ == "__main__":
    run_script(run, parse_args())
