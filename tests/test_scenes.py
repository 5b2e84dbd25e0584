"""Scene sampling: determinism, per-factor streams, config handling."""

from __future__ import annotations

import json

import numpy as np
import pytest

from scgen.errors import ScgenError
from scgen.generator import Generator
from scgen.render.camera.glare import FLARE_REACH_RAD, sun_view
from scgen.scenes import SceneSpec, load_config
from scgen.scenes.config.scene import distance_range_m


def test_same_seed_same_spec_and_json_round_trip(spacecraft):
    cfg = load_config()
    a = Generator(spacecraft, cfg, 3).scene(7)
    b = Generator(spacecraft, cfg, 3).scene(7)
    assert a == b
    assert SceneSpec.from_dict(json.loads(json.dumps(a.to_dict()))) == a
    assert Generator(spacecraft, cfg, 4).scene(7) != a


def test_changing_one_factor_distribution_leaves_the_others_unchanged(spacecraft):
    base = Generator(spacecraft, load_config(), 0)
    lit_cfg = load_config(overrides={"illumination": {"probs": {"weak": 1.0, "normal": 0.0, "strong": 0.0}}})
    lit = Generator(spacecraft, lit_cfg, 0)
    for i in range(30):
        a, b = base.scene(i), lit.scene(i)
        assert b.sun.level == "weak"
        assert a.target == b.target and a.background == b.background and a.props == b.props


def test_pose_is_uniform_on_so3_and_target_stays_in_frame(spacecraft):
    generator = Generator(spacecraft, load_config(), 1)
    specs = [generator.scene(i) for i in range(600)]
    # for a uniform rotation, each column's z-component is uniform on [-1, 1]: mean 0, variance 1/3
    zs = np.array([s.target.R_mat[2, 0] for s in specs])
    assert abs(zs.mean()) < 0.08 and abs(zs.var() - 1 / 3) < 0.05
    K = specs[0].camera.K_mat
    for s in specs:
        uvw = K @ s.target.t_vec
        u, v = uvw[:2] / uvw[2]
        assert 0 <= u <= 639 and 0 <= v <= 479


def test_default_distance_range_gives_60_to_300_px_diameter():
    cfg = load_config()
    lo, hi = distance_range_m(cfg, 0.2)
    # f d / px and back: the same float64 product over its own quotient, two roundings, within 2 u64 of 300
    # and 60 (approx's 1e-6 is loose), where a swapped end or another focal is O(1)
    assert 600 * 0.2 / lo == pytest.approx(300) and 600 * 0.2 / hi == pytest.approx(60)


def test_every_factor_is_labelled(spacecraft):
    s = Generator(spacecraft, load_config(), 0).scene(0)
    assert s.sun.level in ("weak", "normal", "strong")
    assert s.background.kind in ("clean", "complex", "earth", "cluttered")
    assert s.requested_occlusion in ("none", "slight", "moderate", "heavy")


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"sun": {"x": 1}}, "unknown config key 'sun'"),
        ({"illumination": {"nope": 1}}, "unknown config key 'illumination.nope'"),
        ({"distance": {"range_m": [2.0, 1.0]}}, "distance.range_m"),
        ({"illumination": {"probs": {"weak": 0.5, "normal": 0.1, "strong": 0.1}}}, "sum to 1"),
        ({"camera": {"width": 0}}, "camera.width"),
        (
            {"distance": {"min_px": "abc"}},
            "'distance.min_px' must be a number such as 0.001 or 1e-3, got 'abc'",
        ),
        ({"camera": {"cx": "abc"}}, "camera.cx must be a number"),
        ({"illumination": {"probs": {"weak": "x"}}}, "'illumination.probs' must map"),
        ({"shadow": {"coverage": 0.3}}, "'shadow.coverage' must be a list"),
    ],
)
def test_bad_config_is_named(overrides, message):
    with pytest.raises(ScgenError, match=message):
        load_config(overrides=overrides)


def test_resolution_keeps_field_of_view(tmp_path):
    cfg = load_config(resolution=(320, 240))
    assert cfg["camera"]["fx"] == 300 and cfg["camera"]["cx"] == 159.5
    # s = 1/2: fx and the pixel range halve exactly, so f d / px is the same float
    assert distance_range_m(cfg, 0.2) == distance_range_m(load_config(), 0.2)


def test_config_file_toml_and_yaml(tmp_path):
    (tmp_path / "c.toml").write_text("[shadow]\ncaster_prob = 1.0\n")
    (tmp_path / "c.yaml").write_text("shadow:\n  caster_prob: 0.0\n")
    assert load_config(tmp_path / "c.toml")["shadow"]["caster_prob"] == 1.0
    assert load_config(tmp_path / "c.yaml")["shadow"]["caster_prob"] == 0.0


def test_the_sun_is_drawn_near_the_view_for_a_share_of_the_samples_without_a_caster(spacecraft):
    """From its own stream, for ~sun_near_view.prob of the samples without a shadow caster, the sun moves
    to where its image falls in or near the frame: within the lens' flare reach, rendered as a flare.
    Nothing a label depends on moves: pose, camera, occluders, casters and clutter are those drawn
    without it, and samples with a caster keep their sun."""
    cfg = load_config()
    off = load_config(overrides={"illumination": {"sun_near_view": {"prob": 0.0}}})
    near, plain = Generator(spacecraft, cfg, 21), Generator(spacecraft, off, 21)
    moved, no_caster = [], 0
    for i in range(800):
        a, b = near.scene(i), plain.scene(i)
        no_caster += not b.shadow_caster
        assert (a.target, a.camera, a.props, a.requested_occlusion) == (b.target, b.camera, b.props,
                                                                        b.requested_occlusion)  # fmt: skip
        if a.sun != b.sun:
            assert not a.shadow_caster and a.sun.level == b.sun.level
            view = sun_view(a.camera, np.asarray(a.sun.direction))
            assert view is not None and view.off_view_rad < FLARE_REACH_RAD
            moved.append(i)
    expected = cfg["illumination"]["sun_near_view"]["prob"] * no_caster
    assert abs(len(moved) - expected) < 3.5 * np.sqrt(expected), (len(moved), expected)
    with Generator(spacecraft, load_config(resolution=(96, 72)), 21, backend="mitsuba",
                   quality="draft") as renderer:  # fmt: skip
        flared = [renderer.sample(i).buffers.camera.flare for i in moved[:2]]
    assert flared == [True, True]
