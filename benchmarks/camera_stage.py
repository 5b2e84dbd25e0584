"""The camera stage's cost per sample beside the render's, side by side in one run.

    python benchmarks/camera_stage.py [--n 6] [--backends blender,mitsuba]

For each backend at 640x480 (default camera) and 1920x1200 (speedplus camera), renders samples 1..n
(sample 0 warms the renderer up) and prints the median time per sample of the whole render and of the
camera stage inside it (scgen.render.camera.record_image, timed where the backend calls it), and the
stage's share. Target: <= 5 % of a Blender 640x480 sample.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import Any

import click

from scgen.generator import Generator
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


@click.command()
@click.option("--n", type=int, default=6, show_default=True, help="Samples timed per case (after a warm-up).")
@click.option("--backends", default="blender,mitsuba", show_default=True)
@click.option("--quality", default="default", show_default=True)
def main(n: int, backends: str, quality: str) -> None:
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
    main()
