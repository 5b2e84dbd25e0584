"""What both renderers must agree on: quality names, per-sample render seeds, clip range, Earthshine tint.

Each backend translates these into its own settings (Cycles presets, Mitsuba sample counts); keeping
the facts here means a Blender and a Mitsuba render of one SceneSpec differ only by the renderer.
"""

from __future__ import annotations

import numpy as np

from scgen.errors import ScgenError
from scgen.scenes.spec import SceneSpec

QUALITIES = ("draft", "default", "high")
CLIP_START_M, CLIP_END_M = 1e-3, 1e5  # camera clip range: scenes span millimetres to a few metres
EARTHSHINE_COLOUR = (0.8, 0.9, 1.0)  # sunlight reflected by the Earth: bluish (per-channel factor)
LUMA = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 luminance weights of linear RGB
# Mitsuba's film sums a pixel's samples by atomic adds, in no fixed order across threads (now and then one
# level apart): an image rendered on one thread is the same whatever the worker count or shard
MITSUBA_THREADS = 1


def check_quality(quality: str) -> None:
    if quality not in QUALITIES:
        raise ScgenError(f"unknown quality '{quality}' (choose from {', '.join(QUALITIES)})")


def render_seed(spec: SceneSpec) -> int:
    """The path tracer's seed for one sample: fixed by (dataset seed, index), so re-renders are identical."""
    return (spec.seed * 1_000_003 + spec.index) % (2**31)
