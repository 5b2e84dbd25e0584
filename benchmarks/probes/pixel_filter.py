"""What Mitsuba's pixel filter costs, and how wide each filter blurs beside Cycles' (issue 61).

A 640x480 film at 16 spp, one renderer thread, path tracer as scgen's (max_depth 4, a sun): a sphere
covering 0, 10 and 50 % of the frame, rendered with each film filter in turn (3 rounds, A B C D A B C D),
the fastest time per filter printed. Mitsuba splats every sample into each pixel within the filter's
radius, so the cost of an empty pixel is mostly that splat. Then each filter's standard deviation (its
spread, in pixels) beside that of Cycles' Blackman-Harris at scgen's 1.5 px width, whose importance
table spans twice the width given (Cycles' film.cpp), i.e. +-1.5 px.

Usage: python benchmarks/probes/pixel_filter.py [--rounds 3]
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import parser, run_script

from scgen.render.blender.settings import FILTER_WIDTH_PX
from scgen.render.mitsuba.backend import select_variant
from scgen.render.mitsuba.window import PIXEL_FILTER

SIZE, SPP, FOCAL_PX, DEPTH_M = (640, 480), 16, 800.0, 10.0
FILTERS = {  # name: (Mitsuba's film filter, the standard deviation of its weight in px)
    "gaussian 0.5 px (Mitsuba's default; scgen's before)": ({"type": "gaussian"}, 0.5),
    "tent, radius 1 px (scgen's now)": (PIXEL_FILTER, 1 / math.sqrt(6)),
    "gaussian 0.25 px": ({"type": "gaussian", "stddev": 0.25}, 0.25),
    "box": ({"type": "box"}, 1 / math.sqrt(12)),
}


def blackman_harris_spread(width_px: float) -> float:
    """The standard deviation of Cycles' Blackman-Harris filter over [-width, width] (its table's span)."""
    x = np.linspace(-width_px, width_px, 200_001)
    v = 2 * np.pi * (x / (2 * width_px) + 0.5)
    w = 0.35875 - 0.48829 * np.cos(v) + 0.14128 * np.cos(2 * v) - 0.01168 * np.cos(3 * v)
    return float(np.sqrt((w * x * x).sum() / w.sum()))


def scene(rfilter: dict, cover: float) -> mi.Scene:
    """A sphere at DEPTH_M whose disc covers `cover` of the frame, lit by a sun, seen through `rfilter`."""
    radius_px = math.sqrt(cover * SIZE[0] * SIZE[1] / math.pi)
    film = {
        "type": "hdrfilm",
        "width": SIZE[0],
        "height": SIZE[1],
        "pixel_format": "rgba",
        "rfilter": rfilter,
    }
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 4},
        "sensor": {"type": "perspective", "fov": math.degrees(2 * math.atan(SIZE[0] / (2 * FOCAL_PX))),
                   "fov_axis": "x", "film": film, "sampler": {"type": "independent", "sample_count": SPP}},
        "sun": {"type": "directional", "direction": [0.3, -0.5, 1.0], "irradiance": 3.0},
        "ball": {"type": "sphere", "center": [0, 0, DEPTH_M], "radius": radius_px / FOCAL_PX * DEPTH_M,
                 "bsdf": {"type": "roughconductor"}},
    })  # fmt: skip


def run(args) -> None:
    select_variant()
    dr.set_thread_count(1)
    print(f"Mitsuba, {SIZE[0]}x{SIZE[1]}, {SPP} spp, one thread: fastest of {args.rounds} renders, ms")
    for cover in (0.0, 0.1, 0.5):
        scenes = {name: scene(dict(f), cover) for name, (f, _) in FILTERS.items()}
        for s in scenes.values():  # warm-up: each filter's kernel compiled once
            dr.eval(mi.render(s, seed=0))
        best = dict.fromkeys(scenes, math.inf)
        for k in range(args.rounds):
            for name, s in scenes.items():
                tic = time.perf_counter()
                dr.eval(mi.render(s, seed=k + 1))
                dr.sync_thread()
                best[name] = min(best[name], time.perf_counter() - tic)
        print(f"  sphere over {cover:.0%} of the frame: "
              + ", ".join(f"{name.split(' (')[0]} {1000 * t:.0f}" for name, t in best.items()))  # fmt: skip
    print(f"spread (standard deviation, px): Cycles' Blackman-Harris at {FILTER_WIDTH_PX} px "
          f"{blackman_harris_spread(FILTER_WIDTH_PX):.3f}; "
          + ", ".join(f"{name} {spread:.3f}" for name, (_, spread) in FILTERS.items()))  # fmt: skip


if __name__ == "__main__":
    ap = parser(__doc__)
    ap.add_argument("--rounds", type=int, default=3, help="Renders per filter and cover [3].")
    run_script(run, ap.parse_args())
