"""Cycles traces only the region the objects cover, and gives the full frame's labels and image.

Why a region render can equal a full-frame one: the film is transparent and the world black, so a pixel
none of whose samples meets an object renders exactly zero in every pass; the sky and the camera stage
(glare, blur, noise) act afterwards on the full-frame composite. Cycles seeds each pixel's samples from
its full-frame coordinates and decides adaptive sampling per pixel, so without a denoiser every pixel of
the region traces the same paths as in the full frame: the bound on the difference is zero, labels and
image. The denoiser (OIDN) sees the region instead of the frame (another auto-exposure, its filters'
windows cut at the region's edge), so its image differs; the bound there is the preset's own error: the
crop may move the image over the objects by no more (RMS) than the full-frame render already lies from a
many-sample reference, i.e. it keeps the quality the presets are chosen by (bench_blender.py).
"""

from __future__ import annotations

import numpy as np
import pytest

from scgen.generator import Generator
from scgen.io.buffers import Buffers
from scgen.render.blender.backend import BlenderBackend
from scgen.render.blender.scene import border_fractions
from scgen.render.blender.settings import QualityPreset, configure_beauty
from scgen.render.conventions import CLIP_START_M
from scgen.render.region import Region, covered_region, covered_regions, full_frame, paste
from tests.region_cases import APART, CASES, OCCLUDED, partly_out_of_view, rms_over_objects

SIZE = (160, 120)
LABELS = ("depth", "instance", "target_depth", "normal", "sun_blocked")
K = np.array([[100.0, 0.0, 80.0], [0.0, 100.0, 60.0], [0.0, 0.0, 1.0]])


def test_region_is_the_projected_box_widened_by_the_filter_reach_and_the_margin():
    points = np.array([[0.0, 0.0, 1.0], [0.1, 0.2, 1.0]])  # pixels (80, 60) and (90, 80)
    r = covered_region(K, *SIZE, [points], reach_px=0.75, margin_px=0)
    assert (r.x0, r.y0, r.x1, r.y1) == (80, 60, 91, 81)  # centres within 0.75 px: 80..90, 60..80
    r = covered_region(K, *SIZE, [points], reach_px=0.75, margin_px=5)
    assert (r.x0, r.y0, r.x1, r.y1) == (75, 55, 96, 86)
    far = np.array([[10.0, 0.0, 1.0]])  # out of view to the right: nothing added
    assert covered_region(K, *SIZE, [points, far], 0.75, 0).x1 == SIZE[0]
    assert covered_region(K, *SIZE, [points, far], 0.75, 0).x0 == 80


def test_region_is_the_whole_frame_when_an_object_reaches_the_near_plane_or_nothing_is_in_view():
    near = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, CLIP_START_M / 2]])
    assert covered_region(K, *SIZE, [near], 0.75, 0) == full_frame(*SIZE)
    behind = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])  # wraps around the camera
    assert covered_region(K, *SIZE, [behind], 0.75, 0) == full_frame(*SIZE)
    outside = np.array([[-10.0, 0.0, 1.0], [-9.0, 1.0, 1.0]])
    assert covered_region(K, *SIZE, [outside], 0.75, 0) == full_frame(*SIZE)


def test_objects_apart_get_a_region_each_and_overlapping_ones_share_one():
    left, right = np.array([[-0.5, 0.0, 1.0], [-0.4, 0.1, 1.0]]), np.array([[0.4, 0.0, 1.0], [0.5, 0.1, 1.0]])
    own = [covered_region(K, *SIZE, [points], 0.75, 5) for points in (left, right)]
    assert covered_regions(K, *SIZE, [left, right], 0.75, 5) == tuple(own)  # pixels 30..40 and 120..130
    near_left = left + [0.08, 0.0, 0.0]  # 8 px to the right: the widened boxes overlap
    assert covered_regions(K, *SIZE, [left, near_left], 0.75, 5) == (
        covered_region(K, *SIZE, [left, near_left], 0.75, 5),
    )
    outside = np.array([[10.0, 0.0, 1.0]])
    assert covered_regions(K, *SIZE, [left, outside], 0.75, 5) == (own[0],)
    near = np.array([[0.0, 0.0, CLIP_START_M / 2]])
    assert covered_regions(K, *SIZE, [left, near], 0.75, 5) == (full_frame(*SIZE),)


def test_regions_are_disjoint_hold_each_object_and_span_what_one_region_spans():
    rng = np.random.default_rng(0)
    for _ in range(300):
        centres = rng.uniform([-0.7, -0.5, 1.0], [0.7, 0.5, 1.0], (rng.integers(1, 6), 3))
        objects = [c + rng.uniform(-0.1, 0.1, (4, 3)) * [1, 1, 0] for c in centres]  # in view, 1 m away
        regions = covered_regions(K, *SIZE, objects, 0.75, 4)
        assert all(not a.overlaps(b) for i, a in enumerate(regions) for b in regions[i + 1 :])
        for points in objects:
            own = covered_region(K, *SIZE, [points], 0.75, 4)
            assert any(r.around(own) == r for r in regions)  # inside one of them
        box = regions[0]
        for r in regions[1:]:
            box = box.around(r)
        assert box == covered_region(K, *SIZE, objects, 0.75, 4)


@pytest.mark.parametrize("size", [64, 120, 160, 480, 640, 1200, 1920, 4096, 8192])
def test_border_fractions_give_every_pixel_edge_exactly(size):
    """Blender takes a border edge as int(fraction * size), in float32: every edge of every region
    comes back (a fraction of exactly edge / size lost a pixel to rounding for some: 169 rows for 168)."""
    for e in range(size):  # a one-pixel region at every place: every edge from 0 to size, both axes
        r = Region(e, e, e + 1, e + 1, size, size)
        x0, x1, y0, y1 = (int(np.float32(f) * np.float32(size)) for f in border_fractions(r))
        assert (x0, x1, y0, y1) == (e, e + 1, size - e - 1, size - e)


@pytest.fixture(scope="module")
def generator():
    return Generator.load(seed=3, resolution=SIZE, overrides=OCCLUDED)


@pytest.fixture(scope="module")
def draft(generator):
    backend = BlenderBackend(generator.model, quality="draft")
    yield backend
    backend.close()


def both(backend: BlenderBackend, spec) -> tuple[Buffers, Buffers, tuple[Region, ...]]:
    """(full frame, regions, the regions traced) of one spec."""
    backend.trace_region = False
    full = backend.render(spec)
    backend.trace_region = True
    region = backend.render(spec)
    return full, region, backend.scene.regions


@pytest.mark.parametrize("case", list(CASES | APART))
def test_without_a_denoiser_the_region_render_is_the_full_frame_byte_for_byte(generator, draft, case):
    spec = (CASES | APART)[case](generator.scene(0))
    full, region, traced = both(draft, spec)
    assert not any(r.full for r in traced)
    for name in LABELS:
        assert np.array_equal(getattr(full, name), getattr(region, name)), name
    assert np.array_equal(full.rgb, region.rgb)
    assert full.camera == region.camera
    inside = paste(traced, [np.ones((r.y1 - r.y0, r.x1 - r.x0), bool) for r in traced], False)
    assert full.instance.any() and inside[full.instance > 0].all()  # every object pixel was traced
    if case == "partly out of view":
        assert min(r.x0 for r in traced) == 0 and (full.instance[:, 0] == 1).any()
    if case == "occluder across the frame":
        assert any((r.x0, r.x1) == (0, SIZE[0]) for r in traced)
        assert (full.instance[:, 0] == 2).any() and (full.instance[:, -1] == 2).any()
    if case == "sun glare":
        assert full.camera.flare
    if case == "objects apart":
        assert len(traced) == 2 and not inside.all(axis=1).any()  # two, with untraced pixels in every row
        assert {int(full.instance[r.window].max()) for r in traced} == {1, 2}  # one object in each
        # the aux render (read on the target's pixels alone) traces the target's region and not the prop's
        assert draft.target_regions(spec, traced) == tuple(
            r for r in traced if (full.instance[r.window] == 1).any()
        )


def test_denoised_region_render_keeps_the_labels_and_the_presets_quality(generator):
    spec = partly_out_of_view(generator.scene(1))
    backend = BlenderBackend(generator.model, quality="default")
    try:
        full, region, traced = both(backend, spec)
        backend.trace_region = False
        configure_beauty(backend.scene.beauty, QualityPreset(256, 0.001, 8, 4, 4, None), gpu=False)
        reference = backend.render(spec)
    finally:
        backend.close()
    assert not any(r.full for r in traced)
    for name in LABELS:
        assert np.array_equal(getattr(full, name), getattr(region, name)), name
    moved = rms_over_objects(region.rgb, full.rgb, full.instance)
    error = rms_over_objects(full.rgb, reference.rgb, full.instance)
    assert 0 < moved <= error, (moved, error)
