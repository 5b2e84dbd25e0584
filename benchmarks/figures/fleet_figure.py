"""Draw docs/fleet.jpg: the bundled models (scgen/assets), one row each, as `scgen render --model NAME`
renders them close up on a clean sky, the nominal finish, four poses of the same seed.

    python benchmarks/figures/fleet_figure.py [--backend mitsuba] [--quality default] [--out docs/fleet.jpg]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import label, render_figure_args, run_script

from scgen import Generator
from scgen.scenes.bundled_models import BUNDLED_MODELS

PANEL = (320, 240)
POSES = 4  # samples 0..3 of seed 3: the same poses and lighting for every model
OVERRIDES = {  # close up, alone on a clean sky, the nominal finish, normal sunlight from the camera's side
    "distance": {"min_px": 420.0, "max_px": 460.0},  # px at 640 wide: half that in a panel
    "position": {"inside_radius_frac": 1.0},
    "illumination": {
        "probs": {"weak": 0.0, "normal": 1.0, "strong": 0.0},
        "max_phase_deg": 40.0,
        "sun_near_view": {"prob": 0.0, "margin": 0.5},
    },
    "occluders": {"group_probs": {"none": 1.0}, "distractor_prob": 0.0},
    "shadow": {"caster_prob": 0.0},
    "background": {"probs": {"clean": 1.0}},
    "finish": {"mode": "nominal"},
}


def model_row(name: str, render: dict) -> np.ndarray:
    """Four close-up renders of bundled model `name`, the first labelled with its name."""
    with Generator.load(name, seed=3, resolution=PANEL, camera="ideal", overrides=OVERRIDES, **render) as gen:
        panels = [gen.sample(i).buffers.rgb for i in range(POSES)]
    panels[0] = label(panels[0], name)
    return np.concatenate(panels, axis=1)


def run(args: argparse.Namespace) -> None:
    render = {"backend": args.backend, "quality": args.quality}
    sheet = np.concatenate([model_row(name, render) for name in BUNDLED_MODELS], axis=0)
    cv2.imwrite(str(args.out), sheet[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 90])
    print(f"wrote {args.out}")


if __name__ == "__main__":
    run_script(run, render_figure_args(__doc__, "fleet.jpg"))
