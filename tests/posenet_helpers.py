"""Shared by the posenet tests: one small rendered dataset per session."""

from __future__ import annotations

from pathlib import Path

import pytest

from scgen.runner import RenderJob, run_render

N_IMAGES = 24
RESOLUTION = (320, 240)


def posenet_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """24 samples of seed 0 rendered with Mitsuba at 320x240, read-only for tests.

    Cached under the session's base temp dir (rendered to a sibling, then renamed), so every test
    module asking for it shares one rendering.
    """
    out = tmp_path_factory.getbasetemp() / "posenet_ds"
    if not out.is_dir():
        tmp = out.with_name("posenet_ds.partial")
        job = RenderJob(
            out=tmp, n=N_IMAGES, seed=0, backend="mitsuba", quality="draft", resolution=RESOLUTION
        )
        run_render(job, progress=False)
        tmp.rename(out)
    return out


def occluded_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """6 samples of seed 0, all in 'train', each target 80-95 % hidden by an occluder (the heavy group)."""
    out = tmp_path_factory.getbasetemp() / "posenet_occluded_ds"
    if not out.is_dir():
        tmp = out.with_name("posenet_occluded_ds.partial")
        heavy = {"group_probs": {"none": 0.0, "slight": 0.0, "moderate": 0.0, "heavy": 1.0}}
        job = RenderJob(
            out=tmp,
            n=6,
            seed=0,
            backend="mitsuba",
            quality="draft",
            resolution=RESOLUTION,
            overrides={"occluders": {**heavy, "target_r_occ": {"heavy": [0.8, 0.95]}}},
            ratios=(1.0, 0.0, 0.0),
        )
        run_render(job, progress=False)
        tmp.rename(out)
    return out
