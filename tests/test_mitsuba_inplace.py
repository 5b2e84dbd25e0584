"""What the Mitsuba backend writes in place from sample to sample (meshes, lights, finishes) renders what a
new backend renders, and the cull of the target-alone cast drops no triangle a ray hits."""

from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

from scgen.generator import Generator
from scgen.render.mitsuba.backend import MitsubaBackend, select_variant
from scgen.render.mitsuba.lights import directional_frame, irradiance_rgb
from scgen.render.mitsuba.ray_cull import may_hit

TINY = (96, 72)


def hits(corners: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """R x F: whether each ray from the origin crosses each triangle (Moller-Trumbore, float64)."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    e1, e2 = b - a, c - a
    p = np.cross(directions[:, None], e2[None])
    det = np.einsum("fk,rfk->rf", e1, p)
    s = -a[None]
    u = np.einsum("rfk,rfk->rf", s, p) / det
    q = np.cross(s, e1[None])
    v = np.einsum("rk,rfk->rf", directions, q) / det
    t = np.einsum("fk,rfk->rf", e2, q) / det
    return (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)


def test_the_cull_keeps_every_triangle_a_ray_hits():
    """Small triangles before the camera (some reaching behind it) and a cluster of rays: every triangle
    any ray crosses is kept, and most of those far from the cluster are dropped."""
    rng = np.random.default_rng(5)
    centres = rng.uniform([-3, -3, 0.2], [3, 3, 10], (3000, 3))
    corners = centres[:, None] + rng.normal(0, 0.3, (3000, 3, 3))
    directions = rng.normal([0.2, -0.1, 1.0], 0.05, (400, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    kept = may_hit(corners, directions)
    hit = hits(corners, directions).any(axis=0)
    assert hit.sum() > 50  # the rays do meet triangles
    assert kept[hit].all()
    assert kept[(corners[..., 2] <= 0).any(axis=1)].all()  # no box on the image plane: kept
    assert kept.mean() < 0.5


def test_a_light_written_in_place_is_the_light_mitsuba_builds():
    """directional_frame gives, to the bit, the frame Mitsuba's directional emitter builds for a direction
    (any length, any octant), and the irradiance channels are the ones it stores."""
    if select_variant() == "scalar_rgb":
        pytest.skip("written in place only in a JIT variant")
    rng = np.random.default_rng(11)
    for _ in range(200):
        direction = (rng.normal(size=3) * 10.0 ** rng.uniform(-2, 2)).tolist()
        light = {"type": "directional", "direction": direction,
                 "irradiance": {"type": "rgb", "value": rng.uniform(0, 5, 3).tolist()}}  # fmt: skip
        params = mi.traverse(mi.load_dict(light))
        frame = params["to_world"]
        matrix, inverse_transpose = directional_frame(direction)
        assert np.array_equal(np.asarray(frame.matrix, np.float32)[..., 0], matrix), direction
        assert np.array_equal(np.asarray(frame.inverse_transpose, np.float32)[..., 0], inverse_transpose)
        assert np.array_equal(np.asarray(params["irradiance.value"], np.float32)[:, 0], irradiance_rgb(light))


def test_samples_rendered_one_after_another_equal_new_backends():
    """One backend renders samples that differ in everything written in place (target pose and finishes,
    props, sun, the Earth's light): each image and label equals that of a new backend, built for that
    sample alone. Among them is one whose target is seen behind a prop (the culled target-alone cast)."""
    with Generator.load(seed=3, resolution=TINY, backend="mitsuba", quality="draft") as g:
        specs, model = [g.scene(i) for i in range(40)], g.model
    earth = next(s for s in specs if s.background.kind == "earth")
    with_props = [s for s in specs if s.props and s is not earth][:2]
    chosen = [with_props[0], earth, with_props[1]]
    backend = MitsubaBackend(model, quality="draft")
    ours = [backend.render(s) for s in chosen]
    behind_prop = False
    for s, buffers in zip(chosen, ours, strict=True):
        new = MitsubaBackend(model, quality="draft").render(s)
        for name in ("rgb", "depth", "instance", "target_depth", "normal", "sun_blocked"):
            assert np.array_equal(getattr(buffers, name), getattr(new, name)), (s.index, name)
        behind_prop |= bool(((buffers.instance >= 2) & (buffers.target_depth > 0)).any())
    assert behind_prop
