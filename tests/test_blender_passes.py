"""From Cycles passes to Buffers (pure numpy, no bpy): the target-alone render is skipped only when exact."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from scgen.generator import Generator
from scgen.render.blender.backend import props_may_hide_target
from scgen.scenes import load_config
from scgen.scenes.model import load_target


@pytest.fixture(scope="module")
def scene():
    model = load_target()
    cfg = load_config(resolution=(160, 120))
    generator = Generator(model, cfg, 1)
    spec = next(s for s in (generator.scene(i) for i in range(50)) if s.props)
    hull = np.asarray(model.mesh.convex_hull.vertices)
    x = hull @ spec.target.R_mat.T + spec.target.t_vec
    uv = (x[:, :2] / x[:, 2:]) @ spec.camera.K_mat[:2, :2].T + spec.camera.K_mat[:2, 2]
    centre = np.round(uv.mean(0)).astype(int)
    return spec, hull, centre, float(x[:, 2].min()), float(x[:, 2].max())


def _labels(shape: tuple[int, int], pixel: np.ndarray, depth: float) -> tuple[np.ndarray, np.ndarray]:
    instance, z = np.zeros(shape, np.int32), np.zeros(shape, np.float32)
    instance[pixel[1], pixel[0]], z[pixel[1], pixel[0]] = 2, depth
    return instance, z


def test_a_prop_in_front_of_the_target_needs_the_target_alone_render(scene):
    spec, hull, centre, z_near, _ = scene
    instance, depth = _labels((120, 160), centre, 0.5 * z_near)
    assert props_may_hide_target(spec, hull, instance, depth)


def test_props_behind_or_beside_the_target_cannot_hide_it(scene):
    spec, hull, centre, _, z_far = scene
    assert not props_may_hide_target(spec, hull, *_labels((120, 160), centre, 1.01 * z_far))
    corners = np.array([[0, 0], [159, 0], [0, 119], [159, 119]])
    far_corner = corners[np.argmax(np.linalg.norm(corners - centre, axis=1))]
    assert not props_may_hide_target(spec, hull, *_labels((120, 160), far_corner, 0.01))
    no_props = dataclasses.replace(spec, props=())
    assert not props_may_hide_target(no_props, hull, *_labels((120, 160), centre, 0.01))
