"""Time per sample with the real sky and drawn finishes against today's procedural sky and nominal
finishes, on both backends side by side (issue 30: within 10 %).

Each backend renders the same samples under both configs, interleaved (sample i old, then new), with
the ideal camera so only what issue 30 changed differs; the first sample of each config is a warm-up
(it loads Blue Marble and Hipparcos, once per process). Also prints the background image alone per
kind. Usage: python benchmarks/probes/sky_finish.py [--n 12] [--resolution 640x480] [--quality default]
[--backends mitsuba,blender]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import parser, run_script

from scgen import Generator
from scgen.render.sky.backgrounds import background_image

CONFIGS = {
    "before (procedural sky, nominal finish)": {
        "background": {"earth_map": "procedural", "stars": "procedural"}, "finish": {"mode": "nominal"},
    },
    "after (Blue Marble, Hipparcos, varied finish)": {},
}  # fmt: skip
KINDS = ("clean", "complex", "earth", "cluttered")


def time_samples(backend: str, n: int, resolution: tuple[int, int], quality: str) -> dict[str, list[float]]:
    """Seconds per sample (render and annotation) per config, samples 1..n (0 warms up). One renderer
    renders both configs' SceneSpecs (Blender allows one per process)."""
    gens = {name: Generator.load(seed=0, resolution=resolution, backend=backend, quality=quality,
                                 camera="ideal", overrides=o) for name, o in CONFIGS.items()}  # fmt: skip
    renderer = next(iter(gens.values()))
    times: dict[str, list[float]] = {name: [] for name in gens}
    for i in range(n + 1):
        for name, gen in gens.items():
            spec = gen.scene(i)
            t = time.perf_counter()
            renderer.render(spec)
            if i:
                times[name].append(time.perf_counter() - t)
    renderer.close()
    return times


def time_backgrounds(resolution: tuple[int, int], n: int = 8) -> None:
    """The background image alone (shared by both backends), per kind, in ms."""
    for kind in KINDS:
        row = []
        for overrides in CONFIGS.values():
            o = {**overrides, "background": {**overrides.get("background", {}), "probs": {kind: 1.0}}}
            gen = Generator.load(seed=0, resolution=resolution, overrides=o)
            specs = [gen.scene(i) for i in range(n + 1)]
            background_image(specs[0])
            t = time.perf_counter()
            for spec in specs[1:]:
                background_image(spec)
            row.append(1000 * (time.perf_counter() - t) / n)
        print(f"  background {kind:<9} {row[0]:7.1f} ms -> {row[1]:7.1f} ms")


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--n", type=int, default=12)
    ap.add_argument("--resolution", default="640x480")
    ap.add_argument("--quality", default="default")
    ap.add_argument("--backends", default="mitsuba,blender")
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    resolution = tuple(int(x) for x in args.resolution.split("x"))
    print(f"{args.n} samples of seed 0 at {args.resolution}, quality {args.quality}, ideal camera")
    for backend in args.backends.split(","):
        times = time_samples(backend, args.n, resolution, args.quality)
        before, after = (np.array(t) for t in times.values())
        for name, t in times.items():
            print(f"  {backend:<8} {name:<46} mean {np.mean(t):6.3f} s  median {np.median(t):6.3f} s")
        print(f"  {backend:<8} after / before: mean {after.mean() / before.mean():.3f}, "
              f"median of per-sample ratios {np.median(after / before):.3f}")  # fmt: skip
    time_backgrounds(resolution)


if __name__ == "__main__":
    run_script(run, parse_args())
