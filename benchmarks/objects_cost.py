"""The cost of a labelled sample against the number of labelled objects in it (1, 2, 4), side by side.

Each configuration renders the same seed's `--n` samples through `scgen render`'s own run (start-up
included) with `--workers` workers at 640x480: the target alone; the target and a small satellite; the
target, the small satellite and two spent upper stages (the mix of examples/servicer_client.toml). The
configurations run in turn, `--repeat` rounds (1, 2, 4, 1, 2, 4, ...), and each figure is the median, so
a drift in the machine's speed hits all alike. Printed per configuration: seconds a sample (wall), the
ratio to the target alone, and the workers' seconds a sample inside rendering + annotation and writing.

Usage: python benchmarks/objects_cost.py [--backend blender] [--n 24] [--workers 2] [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from harness import parser, positive, run_script

from scgen.run.runner import RenderJob, run_render

OBJECTS: dict[int, list[dict[str, Any]]] = {  # labelled objects in a scene: the [[objects]] beside the target
    1: [],
    2: [{"model": "smallsat"}],
    4: [{"model": "smallsat"}, {"model": "upper_stage", "count": 2}],
}


def measure(job: RenderJob) -> tuple[float, float, float]:
    """(wall s a sample, workers' render + annotate s a sample, their writing s a sample) of one run."""
    t0 = time.perf_counter()
    summary = run_render(job, progress=False)
    wall = (time.perf_counter() - t0) / job.n
    return wall, summary["render_s"] / summary["rendered"], summary["other_s"] / summary["rendered"]


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--backend", default="blender", help="[blender]")
    ap.add_argument("--n", type=positive, default=24, help="samples per run [24]")
    ap.add_argument("--workers", type=positive, default=2, help="[2]")
    ap.add_argument("--repeat", type=positive, default=3, help="rounds over the configurations [3]")
    ap.add_argument("--seed", type=int, default=4, help="[4]")
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    tmp = Path(tempfile.mkdtemp())
    runs: dict[int, list[tuple[float, float, float]]] = {k: [] for k in OBJECTS}
    for r in range(args.repeat):
        for count, objects in OBJECTS.items():
            overrides = {"objects": objects} if objects else {}
            job = RenderJob(
                out=tmp / f"r{r}o{count}", n=args.n, seed=args.seed, backend=args.backend,
                workers=args.workers, resolution=(640, 480), overrides=overrides,
            )  # fmt: skip
            runs[count].append(measure(job))
    medians = {k: tuple(statistics.median(v[i] for v in vals) for i in range(3)) for k, vals in runs.items()}
    print(f"{args.backend}, 640x480, {args.workers} workers, {args.n} samples a run, median of {args.repeat}")
    print(f"  {'objects':>7s} {'s/sample':>9s} {'vs 1':>6s} {'render+annotate s':>18s} {'write s':>8s}")
    for count, (wall, render, write) in medians.items():
        print(f"  {count:7d} {wall:9.3f} {wall / medians[1][0]:6.2f} {render:18.3f} {write:8.3f}")


if __name__ == "__main__":
    run_script(run, parse_args())
