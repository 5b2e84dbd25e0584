"""The camera stage's cost per sample beside the render's, side by side in one run.

    python benchmarks/probes/camera_stage.py [--n 6] [--backends blender,mitsuba]

For each backend at 640x480 (default camera) and 1920x1200 (speedplus camera), renders samples 1..n
(sample 0 warms the renderer up) and prints the median time per sample of the whole render and of the
camera stage inside it (scgen.render.camera.record_image, timed where the backend calls it), and the
stage's share. Target: <= 5 % of a Blender 640x480 sample.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import parser, run_script

from scgen import Generator
from scgen.render.blender import backend as blender
from scgen.render.mitsuba import backend as mitsuba_backend

CASES = (("default", (640, 480)), ("speedplus", (1920, 1200)))


def timed(fn: Callable[..., Any], spent: list[float]) -> Callable[..., Any]:
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        spent.append(time.perf_counter() - t0)
        return out

    return wrapper


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--n", type=int, default=6, help="Samples timed per case, after a warm-up [6].")
    ap.add_argument("--backends", default="blender,mitsuba", help="[blender,mitsuba]")
    ap.add_argument("--quality", default="default", help="[default]")
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    n, backends, quality = args.n, args.backends, args.quality
    modules = {"blender": blender, "mitsuba": mitsuba_backend}
    print(f"{'backend':8} {'camera':10} {'size':>10} {'sample ms':>10} {'stage ms':>9} {'share':>6}")
    for backend in backends.split(","):
        module = modules[backend]
        for camera, resolution in CASES:
            stage: list[float] = []
            original = module.record_image
            module.record_image = timed(original, stage)
            try:
                with Generator.load(seed=1, resolution=resolution, camera=camera, backend=backend,
                                    quality=quality) as gen:  # fmt: skip
                    gen.sample(0)
                    totals = []
                    for i in range(1, n + 1):
                        t0 = time.perf_counter()
                        gen.sample(i)
                        totals.append(time.perf_counter() - t0)
            finally:
                module.record_image = original
            sample_ms, stage_ms = 1e3 * statistics.median(totals), 1e3 * statistics.median(stage[1:])
            size = f"{resolution[0]}x{resolution[1]}"
            print(f"{backend:8} {camera:10} {size:>10} {sample_ms:10.0f} {stage_ms:9.1f} "
                  f"{100 * stage_ms / sample_ms:5.1f}%")  # fmt: skip


if __name__ == "__main__":
    run_script(run, parse_args())
