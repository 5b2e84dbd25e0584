"""Blender labels are exact at pixel centres: they agree with Mitsuba's ray casts and with the model.

Real Cycles renders (default preset: anti-aliasing filter, adaptive sampling, OIDN) of sampled
scenes covering occluders, shadow casters, clutter and Earth backgrounds, at 320x240 (the
sampler keeps the metric distances of 640x480).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import trimesh
from float_bounds import U32_RAY_HIT, median_depth_gap

from scgen.annotate.annotate import annotate
from scgen.generator import Generator
from scgen.io.buffers import TARGET_ID
from scgen.render.blender.backend import BlenderBackend
from scgen.render.mitsuba.backend import MitsubaBackend
from scgen.scenes import load_config
from scgen.scenes.model import load_target

N_SAMPLES = 8  # seed 0, samples 0-7: clutter, occluders of every group, shadow casters, Earth, no props


@pytest.fixture(scope="module")
def model():
    return load_target()


@pytest.fixture(scope="module")
def rendered(model):
    cfg = load_config(resolution=(320, 240))
    generator = Generator(model, cfg, 0)
    specs = [generator.scene(i) for i in range(N_SAMPLES)]
    blender = BlenderBackend(model, quality="default", device="cpu")
    try:
        b = [blender.render(s) for s in specs]
    finally:
        blender.close()
    mitsuba = MitsubaBackend(model, quality="draft")
    return specs, b, [mitsuba.render(s) for s in specs]


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max(1, (a | b).sum()))


def _shadow_edges(blocked: np.ndarray) -> np.ndarray:
    """Pixels whose 3x3 neighbourhood holds both blocked and unblocked pixels."""
    b = blocked.astype(np.uint8)
    kernel = np.ones((3, 3), np.uint8)
    return cv2.dilate(b, kernel) != cv2.erode(b, kernel)


def test_samples_exercise_every_label(rendered):
    specs, b, m = rendered
    assert any(s.background.kind == "earth" for s in specs)
    assert any(not s.props for s in specs)
    assert sum(int(x.sun_blocked.sum()) for x in m) > 100  # cast shadows on the target
    occluded = [int(((x.target_depth > 0) & (x.instance != TARGET_ID)).sum()) for x in m]
    assert sum(occluded) > 100  # target pixels hidden by props


def test_masks_agree_with_mitsuba(rendered):
    for spec, b, m in zip(*rendered, strict=True):
        visible = _iou(b.instance == TARGET_ID, m.instance == TARGET_ID)
        full = _iou(b.target_depth > 0, m.target_depth > 0)
        assert visible >= 0.98 and full >= 0.98, (spec.index, visible, full)
        assert (b.instance == m.instance).mean() >= 0.999, spec.index


def test_depth_agrees_with_mitsuba(rendered, model):
    """At the median pixel both hit, the two depths agree to float32's rounding of one ray's hit
    (float_bounds.median_depth_gap), where a ray through another point of its pixel moves them by far more."""
    for spec, b, m in zip(*rendered, strict=True):
        for name in ("depth", "target_depth"):
            gap = median_depth_gap(getattr(b, name), getattr(m, name), spec.target.t_vec, model.diameter)
            assert gap <= U32_RAY_HIT, (spec.index, name, gap)


def test_normals_and_sun_visibility_agree_with_mitsuba(rendered):
    for spec, b, m in zip(*rendered, strict=True):
        on_target = (b.instance == TARGET_ID) & (m.instance == TARGET_ID)
        cos = (b.normal * m.normal).sum(-1)[on_target]
        assert (cos > 0.999).mean() >= 0.99, spec.index
        facing = on_target & (m.normal @ np.asarray(spec.sun.direction, np.float32) > 0)
        differ = facing & (b.sun_blocked != m.sun_blocked)
        assert differ.sum() <= 0.01 * facing.sum() + 1, spec.index
        assert not (differ & ~_shadow_edges(m.sun_blocked)).any(), spec.index  # rays grazing a caster's edge
        assert annotate(spec, b).shadow_fraction == pytest.approx(annotate(spec, m).shadow_fraction, abs=0.02)


def test_xyz_reprojects_to_pixel_centres_and_lies_on_the_model(rendered, model):
    query = trimesh.proximity.ProximityQuery(model.mesh)
    for spec, b, _ in zip(*rendered, strict=True):
        ann = annotate(spec, b)
        v, u = np.nonzero(ann.mask_visib)
        if len(u) == 0:
            continue
        C = ann.xyz[v, u].astype(np.float64)
        x = (C @ spec.target.R_mat.T + spec.target.t_vec) @ spec.camera.K_mat.T
        err_px = np.hypot(x[:, 0] / x[:, 2] - u, x[:, 1] / x[:, 2] - v)
        assert (err_px <= 0.5).mean() >= 0.995, spec.index
        off_surface = np.abs(query.signed_distance(C))  # silhouette pixels included
        assert (off_surface <= 0.005 * model.diameter).mean() >= 0.99, spec.index
