"""Draw docs/real_sky.jpg (issue 30): real renders through the ideal camera, three rows of four panels.

    python benchmarks/figures/sky_figure.py [--backend mitsuba] [--quality default] [--out docs/real_sky.jpg]

1. The Blue Marble Earth: two low-orbit limbs and two distant discs (samples of seed 1 with an Earth).
2. The Hipparcos sky behind the target: one scene at the true star brightness (black, as in flight
   images), +20 EV and +24 EV of background.stars_boost_ev, and a `complex` sky: the sunlit Moon.
3. The target's finish: the scene of row 2 with the nominal finish and three drawn finishes.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import label, render_figure_args, run_script

from scgen import Generator
from scgen.scenes.finish import finish_group, sample_finish
from scgen.scenes.rng import factor_rng

PANEL = (320, 240)
CLOSE_UP = {"distance": {"min_px": 330.0, "max_px": 360.0}, "occluders": {"group_probs": {"none": 1.0},
            "distractor_prob": 0.0}, "shadow": {"caster_prob": 0.0}}  # fmt: skip


def _generator(overrides: dict, seed: int, **render) -> Generator:
    return Generator.load(seed=seed, resolution=PANEL, camera="ideal", overrides=overrides, **render)


def earth_row(render: dict) -> list[np.ndarray]:
    with _generator({"background": {"probs": {"earth": 1.0}}}, 1, **render) as gen:
        specs = [gen.scene(i) for i in range(40)]
        limbs = [s for s in specs if s.background.params["limb"]][:2]
        discs = [s for s in specs if not s.background.params["limb"]][:2]
        panels = []
        for spec in limbs + discs:
            p = spec.background.params
            text = f"{'limb' if p['limb'] else 'disc'} {p['angular_radius_deg']:.0f} deg"
            panels.append(label(gen.render(spec).buffers.rgb, text))
    return panels


def stars_row(render: dict) -> list[np.ndarray]:
    panels = []
    for boost in (0.0, 20.0, 24.0):
        overrides = {**CLOSE_UP, "background": {"probs": {"clean": 1.0}, "stars_boost_ev": boost}}
        with _generator(overrides, 2, **render) as gen:
            panels.append(label(gen.sample(0).buffers.rgb, f"Hipparcos, stars_boost_ev {boost:g}"))
    overrides = {"background": {"probs": {"complex": 1.0}}}
    with _generator(overrides, 2, **render) as gen:
        panels.append(label(gen.sample(1).buffers.rgb, "complex: the Moon"))
    return panels


def finish_row(render: dict) -> list[np.ndarray]:
    overrides = {**CLOSE_UP, "background": {"probs": {"clean": 1.0}}, "finish": {"mode": "nominal"}}
    with _generator(overrides, 2, **render) as gen:
        spec = gen.scene(0)
        panels = [label(gen.render(spec).buffers.rgb, "finish: nominal")]
        cfg = {"mode": "varied", "swap_prob": 0.2, "jitter": 1.0, "nominal_prob": 0.0}
        for draw in (3, 5, 11):
            finish = sample_finish(factor_rng(2, draw, "finish"), cfg)
            panels.append(label(gen.render(replace(spec, finish=finish)).buffers.rgb,
                                 f"finish: {finish_group(finish)} (draw {draw})"))  # fmt: skip
    return panels


def run(args: argparse.Namespace) -> None:
    render = {"backend": args.backend, "quality": args.quality}
    rows = [np.concatenate(row(render), axis=1) for row in (earth_row, stars_row, finish_row)]
    cv2.imwrite(str(args.out), np.concatenate(rows, axis=0)[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 90])
    print(f"wrote {args.out}")


if __name__ == "__main__":
    run_script(run, render_figure_args(__doc__, "real_sky.jpg"))
