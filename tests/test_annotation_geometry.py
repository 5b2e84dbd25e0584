"""The xyz maps are exact: they reproject onto their own pixels and lie on the model's surface."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import trimesh

from scgen.annotate.annotate import mask_bbox
from scgen.dataset.validate import reprojection_error
from scgen.generator import Generator
from scgen.scenes import load_config
from scgen.scenes.bundled_models import BUNDLED_MODELS
from scgen.scenes.factors import occlusion_group
from scgen.scenes.model import load_target, normalise_parts

RES = (320, 240)


def odd_mesh_model():
    """A second, differently shaped target: a torus pierced by an off-centre rod and a wedge."""
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.25)
    rod = trimesh.creation.cylinder(radius=0.08, segment=[[0.3, -1.6, 0.0], [0.3, 1.2, 0.4]])
    wedge = trimesh.creation.box(extents=[0.6, 0.3, 0.9])
    wedge.apply_translation([-1.1, 0.4, 0.3])
    return normalise_parts([("white_paint", torus), ("brushed_metal", rod), ("mli_gold", wedge)], 0.2, "odd")


def rendered_samples(model, n: int = 4):
    cfg = load_config(resolution=RES, overrides={"distance": {"range_m": [0.45, 1.2]}})
    with Generator(model, cfg, 11, backend="mitsuba", quality="draft") as generator:
        for i in range(n):
            sample = generator.sample(i)
            yield sample.spec, sample.buffers, sample.annotation


@pytest.mark.parametrize(
    "make_model",
    [odd_mesh_model, *(functools.partial(load_target, name) for name in BUNDLED_MODELS)],
    ids=["odd_mesh", *BUNDLED_MODELS],
)
def test_xyz_reprojects_and_lies_on_surface(make_model):
    model = make_model()
    surface = trimesh.proximity.ProximityQuery(model.mesh)
    checked = 0
    for spec, _, ann in rendered_samples(model):
        vs, us = np.nonzero(ann.mask_visib)
        if len(us) < 20:
            continue
        C = ann.xyz[vs, us].astype(np.float64)
        err = reprojection_error(C, us, vs, spec.camera, spec.target.R_mat, spec.target.t_vec)
        assert (err <= 0.5).mean() >= 0.995
        _, dist, _ = surface.on_surface(C)
        assert (dist <= 0.005 * model.diameter).mean() >= 0.99, f"max {dist.max():.5f} m"
        checked += 1
    assert checked >= 2


def test_masks_boxes_and_occlusion_are_consistent():
    for _spec, buffers, ann in rendered_samples(load_target(), n=6):
        assert not (ann.mask_visib & ~ann.mask).any()
        assert ann.bbox_obj == mask_bbox(ann.mask) and ann.bbox_visib == mask_bbox(ann.mask_visib)
        hidden = ann.mask & ~ann.mask_visib
        if not hidden.any():
            assert ann.r_occ == 0 and (ann.mask == ann.mask_visib).all()
            assert occlusion_group(ann.r_occ) == "none"
        else:  # every hidden pixel is covered by a prop in front of the target
            assert (buffers.instance[hidden] >= 2).all()
            assert (buffers.depth[hidden] < buffers.target_depth[hidden]).all()
        assert ann.r_occ == pytest.approx(1 - ann.mask_visib.sum() / max(1, ann.mask.sum()))


def test_no_props_means_no_occlusion_and_no_cast_shadow():
    model = load_target()
    cfg = load_config(
        resolution=RES,
        overrides={
            "occluders": {"group_probs": {"none": 1.0, "slight": 0.0, "moderate": 0.0, "heavy": 0.0},
                          "distractor_prob": 0.0},
            "shadow": {"caster_prob": 0.0},
            "background": {"probs": {"clean": 1.0, "complex": 0.0, "earth": 0.0, "cluttered": 0.0}},
        },
    )  # fmt: skip
    sample = Generator(model, cfg, 0, backend="mitsuba", quality="draft").sample(1)
    spec, ann = sample.spec, sample.annotation
    assert spec.props == ()
    assert ann.r_occ == 0 and (ann.mask == ann.mask_visib).all() and ann.shadow_fraction == 0


def test_shadow_caster_in_the_sun_path_shades_the_target():
    model = load_target()
    cfg = load_config(resolution=RES, overrides={"shadow": {"caster_prob": 1.0, "offset_diam": [0.0, 0.0],
                                                            "size_diam": [2.0, 2.0]}})  # fmt: skip
    ann = Generator(model, cfg, 0, backend="mitsuba", quality="draft").sample(2).annotation
    assert ann.shadow_fraction > 0.9 and ann.shadow_label == "yes"
