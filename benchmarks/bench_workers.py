"""Images/s at 1 and 2 worker processes in one run, and the scaling ratio (target >= 0.9x linear).

Usage: python benchmarks/bench_workers.py [--backend blender] [--n 16] [--quality default]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from scgen.runner import RenderJob, run_render


def images_per_second(backend: str, n: int, workers: int, quality: str, out: Path) -> float:
    job = RenderJob(out=out, n=n, seed=0, backend=backend, quality=quality, workers=workers)
    t0 = time.perf_counter()
    run_render(job, progress=False)
    return n / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--backend", default="blender")
    ap.add_argument("--n", type=int, default=16)
    ap.add_argument("--quality", default="default")
    args = ap.parse_args()
    cores = os.cpu_count() or 1
    tmp = Path(tempfile.mkdtemp())
    rates = {k: images_per_second(args.backend, args.n, k, args.quality, tmp / f"w{k}") for k in (1, cores)}
    print(f"{args.backend} ({args.quality}, 640x480), {args.n} samples per run, {cores} cores")
    for k, r in rates.items():
        print(f"  {k} worker(s): {r:.3f} images/s  ({1 / r:.2f} s/image, all included)")
    gain = rates[cores] / rates[1]
    print(f"  scaling: {gain:.2f}x with {cores} workers = {gain / cores:.2f} of linear")


if __name__ == "__main__":
    main()
