"""The Mitsuba backend's frozen render (drjit.freeze) replays what tracing the path tracer renders."""

from __future__ import annotations

import dataclasses

import numpy as np
from trimesh.transformations import rotation_matrix

from scgen.generator import Generator
from scgen.render.mitsuba.backend import MitsubaBackend
from scgen.scenes.spec import Pose

TINY = (96, 72)


def turned(pose: Pose, degrees: float) -> Pose:
    """The pose turned about the camera's y axis, about the target's origin."""
    R = rotation_matrix(np.radians(degrees), [0.0, 1.0, 0.0])[:3, :3] @ pose.R_mat
    return Pose(tuple(R.ravel()), pose.t)


def test_a_replayed_render_equals_a_traced_one():
    """One backend renders a sample with its target turned a little between renders (props, finish,
    lights kept): after the first renders it replays its recording, and each image and label equals that
    of a new backend, which traces the same spec afresh. The target's meshes are refilled in place
    between replays; a recording that read the buffers it was recorded with would show the old pose."""
    with Generator.load(seed=3, resolution=TINY, backend="mitsuba", quality="draft") as g:
        spec, model = g.scene(4), g.model
    specs = [dataclasses.replace(spec, target=turned(spec.target, a)) for a in (0.0, 1.5, 3.0, 4.5, 6.0)]
    backend = MitsubaBackend(model, quality="draft")
    replayed = [backend.render(s) for s in specs]
    assert backend.recordings <= 2  # the first render records; a second one may, as freezing turns
    for s, ours in zip(specs, replayed, strict=True):  # the inputs that changed into opaque ones
        traced = MitsubaBackend(model, quality="draft").render(s)
        assert np.array_equal(ours.rgb, traced.rgb), s.target
        assert np.array_equal(ours.depth, traced.depth), s.target
    assert not np.array_equal(replayed[0].rgb, replayed[-1].rgb)  # the turns show
