"""Shadow casters: the measured shadow label follows them, and they never occlude the target."""

from __future__ import annotations

import pytest

from scgen.annotate import annotate
from scgen.render.mitsuba.backend import MitsubaBackend
from scgen.scenes import load_config, sample_scene
from scgen.scenes.model import load_target
from scgen.scenes.silhouette import TargetShape

SMALL = (320, 240)
NO_OCCLUDERS = {"group_probs": {"none": 1.0}, "distractor_prob": 0.0}


@pytest.fixture(scope="module")
def setup():
    model = load_target()
    return model, TargetShape.from_mesh(model.mesh, model.diameter), MitsubaBackend(model, quality="draft")


@pytest.mark.parametrize("caster_prob, expect_yes", [(1.0, True), (0.0, False)])
def test_shadow_label_follows_the_caster(setup, caster_prob, expect_yes):
    model, shape, backend = setup
    cfg = load_config(overrides={"shadow": {"caster_prob": caster_prob}, "occluders": NO_OCCLUDERS,
                                 "background": {"probs": {"clean": 1.0}}}, resolution=SMALL)  # fmt: skip
    anns = []
    for i in range(10):
        spec = sample_scene(3, i, cfg, shape)
        assert spec.shadow_caster == expect_yes
        anns.append(annotate(spec, backend.render_geometry(spec)))
    yes = sum(a.shadow_label == "yes" for a in anns)
    assert (yes >= 8) if expect_yes else (yes == 0), [a.shadow_fraction for a in anns]
    assert all(a.r_occ == 0.0 for a in anns)  # a caster shades the target but never hides it
