"""Occluders are aimed at a requested occlusion group; the sampler's silhouettes match the render."""

from __future__ import annotations

import numpy as np
import pytest

from scgen.annotate import annotate
from scgen.render.mitsuba.backend import MitsubaBackend
from scgen.scenes import load_config, sample_scene
from scgen.scenes.model import load_target
from scgen.scenes.props import bounding_radius, local_pieces
from scgen.scenes.silhouette import TargetShape, camera_view

SMALL = (320, 240)


@pytest.fixture(scope="module")
def model():
    return load_target()


@pytest.fixture(scope="module")
def shape(model):
    return TargetShape.from_mesh(model.mesh, model.diameter)


@pytest.fixture(scope="module")
def backend(model):
    return MitsubaBackend(model, quality="draft")


def only(group: str, **extra) -> dict:
    probs = {g: float(g == group) for g in ("none", "slight", "moderate", "heavy")}
    overrides = {"occluders": {"group_probs": probs, **extra}, "shadow": {"caster_prob": 0.0}}
    return load_config(overrides=overrides, resolution=SMALL)


@pytest.mark.parametrize("group, check", [
    ("heavy", lambda r: r > 0.4),
    ("moderate", lambda r: 0.2 < r <= 0.4),
    ("slight", lambda r: 0.0 < r <= 0.2),
    ("none", lambda r: r == 0.0),
])  # fmt: skip
def test_requested_group_is_what_the_render_measures(model, shape, backend, group, check):
    cfg = only(group, distractor_prob=1.0)
    r_occ = [annotate(s, backend.render_geometry(s)).r_occ
             for s in (sample_scene(5, i, cfg, shape) for i in range(8))]  # fmt: skip
    assert sum(check(r) for r in r_occ) >= 7, r_occ


def test_sampler_silhouette_matches_the_rendered_mask(model, shape, backend):
    cfg = only("none", distractor_prob=0.0)
    for i in range(4):
        spec = sample_scene(2, i, cfg, shape)
        K = spec.camera.K_mat
        view = camera_view(K, *SMALL, shape.in_camera(spec.target.R_mat, spec.target.t_vec), max_side=10_000)
        mask = annotate(spec, backend.render_geometry(spec)).mask
        x0, y0 = (int(v) for v in view.grid.origin)
        crop = mask[y0 : y0 + view.grid.height, x0 : x0 + view.grid.width]
        iou = (crop & view.mask).sum() / (crop | view.mask).sum()
        assert iou > 0.9 and crop.sum() == mask.sum()


def test_aim_without_rendering_hits_every_group(model, shape):
    """The sampler's own overlap estimate lands in the requested group for nearly every sample."""
    for group, (lo, hi) in {"slight": (0.0, 0.2), "moderate": (0.2, 0.4), "heavy": (0.4, 1.0)}.items():
        cfg = only(group)
        hits = 0
        for i in range(30):
            spec = sample_scene(7, i, cfg, shape)
            occ = spec.occluders[0]
            target = shape.in_camera(spec.target.R_mat, spec.target.t_vec)
            view = camera_view(spec.camera.K_mat, *SMALL, target)
            pieces = [v @ occ.pose.R_mat.T + occ.pose.t_vec
                      for v, _ in local_pieces(occ.shape, np.asarray(occ.size), occ.seed)]  # fmt: skip
            hits += lo < view.overlap(pieces) <= hi
        assert hits >= 27, (group, hits)


def test_occluders_stay_in_front_of_the_target(model, shape):
    cfg = load_config(resolution=SMALL)
    for i in range(60):
        spec = sample_scene(0, i, cfg, shape)
        for occ in spec.occluders:
            far_side = occ.pose.t_vec[2] + bounding_radius(occ.shape, np.asarray(occ.size))
            assert far_side < spec.target.t_vec[2] - shape.radius
