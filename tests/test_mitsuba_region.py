"""Mitsuba path-traces only a window over the region the objects cover, and keeps the full frame's labels
and image quality.

The labels are cast through every pixel centre either way: byte-identical. The image is not: Mitsuba's
independent sampler seeds each sample by its place in the render's wavefront (sample_tea_32(seed, lane)),
not by its pixel, so a window draws other random numbers for the same pixel than the full frame does. The
window render is then another draw of the same estimator (the camera stage's exposure and saturated share,
read from the image, may move with it): unbiased if every sample that reaches a pixel of the region is
drawn in both (mitsuba.window's REACH_PX). So the image is held to the Blender region test's bound at a
sample count where the draws' own noise is small: rendered at REFERENCE_SPP, the window may move the
image over the objects by no more (RMS) than the preset's full-frame render lies from that reference. Two
draws at 16x the samples differ by sqrt(2)/4 of the preset's noise (RMS), a third of the bound; a window
misplaced by a pixel, or a filter's normalisation cut at its edge, errs by the objects' contrast at their
edges. (Not at the preset's 16 samples: with the sun in view a few bright samples carry much of the
error, and two such draws' RMS errors differed by 60 %.)
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from scgen.generator import Generator
from scgen.io.buffers import Buffers
from scgen.render.mitsuba.backend import MitsubaBackend
from scgen.render.mitsuba.window import RUNGS, film_window, ladder_side
from scgen.render.region import Region
from scgen.scenes.spec import Pose
from tests.region_cases import CASES, OCCLUDED, rms_over_objects

SIZE = (160, 120)
LABELS = ("depth", "instance", "target_depth", "normal", "sun_blocked")
REFERENCE_SPP = 256  # 16x the preset's samples: a quarter of its noise (RMS)


@pytest.mark.parametrize("side", [120, 160, 480, 640, 1200, 1920])
def test_the_window_holds_the_region_inside_the_frame_at_a_ladder_size(side):
    """Every region along one axis (both axes alike): a window inside the frame that holds it, at most
    twice its size (or an eighth of the frame's), of one of four sizes."""
    sizes = set()
    for lo in range(0, side, 7):
        for hi in range(lo + 1, side + 1, 5):
            w = film_window(Region(lo, 0, hi, side, side, side + 1))
            assert 0 <= w.x0 <= lo and hi <= w.x1 <= side
            n = w.x1 - w.x0
            assert n == side or n <= max(2 * (hi - lo), math.ceil(side / 8))
            assert n == ladder_side(hi - lo, side)
            sizes.add(n)
    assert len(sizes) <= len(RUNGS)
    assert film_window(Region(0, 0, side, side, side, side)).full


@pytest.fixture(scope="module")
def generator():
    return Generator.load(seed=3, resolution=SIZE, overrides=OCCLUDED)


@pytest.fixture(scope="module")
def backend(generator):
    return MitsubaBackend(generator.model, quality="default")


@pytest.fixture(scope="module")
def many(generator):
    backend = MitsubaBackend(generator.model, quality="default")
    backend.spp = REFERENCE_SPP  # before its first render: its sensors take it
    return backend


def both(backend: MitsubaBackend, spec) -> tuple[Buffers, Buffers, Region]:
    """(full frame, window, the window) of one spec."""
    backend.trace_region = False
    full = backend.render(spec)
    backend.trace_region = True
    region = backend.render(spec)
    return full, region, backend.window


@pytest.mark.parametrize("case", list(CASES))
def test_the_window_render_keeps_the_labels_and_the_image_quality(generator, backend, many, case):
    spec = CASES[case](generator.scene(0))
    full, region, window = both(backend, spec)
    assert not window.full
    for name in LABELS:
        assert np.array_equal(getattr(full, name), getattr(region, name)), name
    assert full.camera.flare == region.camera.flare  # its exposure and saturated share: the image's
    rows, cols = np.nonzero(full.instance)
    assert rows.size and window.y0 <= rows.min() and rows.max() < window.y1
    assert window.x0 <= cols.min() and cols.max() < window.x1
    reference, moved_image, same_window = both(many, spec)
    assert same_window == window
    moved = rms_over_objects(moved_image.rgb, reference.rgb, full.instance)
    error = rms_over_objects(full.rgb, reference.rgb, full.instance)
    assert 0 < moved <= error, (moved, error)
    if case == "partly out of view":
        assert window.x0 == 0 and (full.instance[:, 0] == 1).any()
    if case == "occluder across the frame":
        assert (window.x0, window.x1) == (0, SIZE[0])
    if case == "sun glare":
        assert full.camera.flare


def test_a_replayed_window_render_equals_a_traced_one(generator):
    """A backend renders the target moved a few pixels at a time (the window's size kept, its place
    moved): after the first render it replays its recording, with the window's camera moved, and each
    image equals that of a new backend tracing the same spec afresh."""
    spec = generator.scene(2)
    K = spec.camera.K_mat
    z = spec.target.t_vec[2]
    moved = [tuple(spec.target.t_vec + [dx * z / K[0, 0], 0.0, 0.0]) for dx in (0.0, 3.0, 6.0)]
    specs = [replace(spec, target=Pose(spec.target.R, t), props=()) for t in moved]  # the target's window
    ours = MitsubaBackend(generator.model, quality="draft", region=True)
    windows = []
    for s in specs:
        image = ours.render(s).rgb
        windows.append(ours.window)
        traced = MitsubaBackend(generator.model, quality="draft", region=True)
        assert np.array_equal(image, traced.render(s).rgb)
        assert traced.window == ours.window
    assert len({w.x0 for w in windows}) > 1 and len({w.x1 - w.x0 for w in windows}) == 1
    assert ours.recordings <= 2
