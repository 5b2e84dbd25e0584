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


def images_per_second(backend: str, n: int, workers: int, threads: int, quality: str, out: Path) -> float:
    job = RenderJob(out=out, n=n, seed=0, backend=backend, quality=quality, workers=workers, threads=threads)
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
    runs = {  # (workers, renderer threads per worker)
        "1 worker x 1 thread": (1, 1),
        f"{cores} workers x 1 thread": (cores, 1),
        f"1 worker x {cores} threads": (1, cores),
    }
    rates = {
        name: images_per_second(args.backend, args.n, w, t, args.quality, tmp / f"w{w}t{t}")
        for name, (w, t) in runs.items()
    }
    print(f"{args.backend} ({args.quality}, 640x480), {args.n} samples per run, {cores} cores")
    for name, r in rates.items():
        print(f"  {name:<22s} {r:.3f} images/s  ({1 / r:.2f} s/image, all included)")
    names = list(rates)
    ratio = rates[names[1]] / rates[names[0]]
    print(f"  process scaling: {ratio:.2f}x with {cores} workers = {ratio / cores:.2f} of linear")
    versus = rates[names[1]] / rates[names[2]]
    print(f"  {cores} single-thread workers vs one {cores}-thread worker: {versus:.2f}x")


if __name__ == "__main__":
    main()
