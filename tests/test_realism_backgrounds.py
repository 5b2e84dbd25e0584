"""Backgrounds: deterministic, visibly different per kind; the user's own images as a fifth kind."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from scgen.errors import ScgenError
from scgen.generator import Generator
from scgen.render.conventions import LUMA
from scgen.render.lighting import exposure_scale
from scgen.render.sky.backgrounds import background_image, srgb_to_linear
from scgen.render.sky.moon_surface import moon_surface
from scgen.scenes import load_config
from scgen.scenes.geometry import unit_sphere_hits
from scgen.scenes.model import load_target
from scgen.scenes.sky import background_holds

SMALL = (160, 120)


def kind_specs(kind: str, n: int = 4, **background) -> list:
    cfg = load_config(overrides={"background": {"probs": {kind: 1.0}, **background}}, resolution=SMALL)
    generator = Generator(load_target(), cfg, 2)
    return [generator.scene(i) for i in range(n)]


def test_background_is_deterministic_and_kinds_differ():
    mean = {}
    for kind in ("clean", "complex", "earth", "cluttered"):
        specs = kind_specs(kind, stars="procedural")  # the kinds' star densities (the real sky is one sky)
        images = [background_image(s) for s in specs]
        assert np.array_equal(images[0], background_image(specs[0]))
        assert images[0].shape == (SMALL[1], SMALL[0], 3) and images[0].dtype == np.float32
        mean[kind] = float(np.mean(images))
    assert mean["clean"] < mean["cluttered"] < mean["complex"] < mean["earth"]
    assert mean["clean"] < 0.005  # black space with sparse stars


def test_the_complex_sky_is_the_sunlit_moon_at_its_albedo_and_nothing_else_glows():
    """The Moon's lit pixels are a Lambertian surface of the Moon's albedo under the sun (their mean
    value over the sphere's own cosine: 0.08-0.18, the Moon's geometric albedo 0.12); off the Moon the
    sky holds only the Hipparcos stars at their true brightness (the brightest, Sirius, about 1e-4 of a
    sunlit plate), no nebula or band of glow."""
    for spec in kind_specs("complex", n=6):
        image = background_image(spec)
        params = spec.background.params
        c, rho = np.asarray(params["centre_dir"]), np.deg2rad(params["angular_radius_deg"])
        rays = spec.camera.pixel_directions()
        hit, n, _, _ = unit_sphere_hits(rays, c / np.sin(rho))
        plate = spec.sun.irradiance * exposure_scale(spec)  # a white plate facing the sun
        assert image[~hit].max() < 2e-4 * plate, image[~hit].max() / plate
        facing = n @ np.asarray(spec.sun.direction)
        lit = facing > 0.3
        if lit.sum() > 200:
            albedo = (image[hit][lit] @ LUMA).sum() / (plate * facing[lit]).sum()
            assert 0.08 < albedo < 0.18, albedo
        assert background_holds(spec.background.kind, params) in ("moon limb", "moon disc")


def pixel_scale_contrast(distance: float, w: int = 160, h: int = 120, focal: float = 300.0) -> float:
    """The Moon's reflectance seen from `distance` Moon radii from its centre, looking at it, under an
    oblique sun: the RMS of its 2-px high-pass over its mean (the relief and albedo a pixel resolves)."""
    u, v = np.meshgrid(np.arange(w) - w / 2 + 0.5, np.arange(h) - h / 2 + 0.5)
    rays = np.stack([u / focal, v / focal, np.ones_like(u)], -1).reshape(-1, 3)
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    centre = np.array([0.0, 0.0, distance])
    hit, n, _, _ = unit_sphere_hits(rays, centre)
    turn = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0]  # some place on the Moon
    east = np.cross(turn[2], n)
    east /= np.linalg.norm(east, axis=1, keepdims=True)
    footprint = np.linalg.norm(n + centre, axis=1) / focal / np.sqrt(-np.sum(n * rays[hit], axis=1))
    sun = np.array([0.6, -0.3, -0.74]) / np.linalg.norm([0.6, -0.3, -0.74])  # 48 deg above the view's plane
    image = np.zeros(len(rays))
    image[hit] = moon_surface(n @ turn.T, n, east, np.cross(n, east), footprint, sun)
    image = image.reshape(h, w)
    inside = cv2.erode(hit.reshape(h, w).astype(np.uint8), np.ones((9, 9))) > 0
    high_pass = (image - cv2.GaussianBlur(image, (0, 0), 2.0))[inside]
    return float(np.sqrt(np.mean(high_pass**2)) / np.mean(image[inside]))


def test_the_moon_is_cratered_at_the_pixel_scale_from_low_orbit_to_a_far_disc():
    """The craters a pixel resolves come from the procedural field at every distance, so the close limb is
    no magnified map (issue 53: blotches): from 100 km up (1.06 radii) the pixel-scale contrast is over a
    sixth of a far disc's (measured 0.087 against 0.234; the maps alone gave 0.006 against 0.278), and over
    half of it with the disc seen twice as large (4 radii: 0.183)."""
    close, far = pixel_scale_contrast(1.06), pixel_scale_contrast(8.0)
    assert close > far / 6, (close, far)
    assert 0.05 < far < 1.0, far
    assert pixel_scale_contrast(4.0) > 0.5 * far


def test_earth_shows_a_lit_part_in_the_frame():
    for spec in kind_specs("earth", n=8):
        lit = background_image(spec).max(axis=2) > 0.02 * spec.sun.irradiance / 1361.0
        assert lit.mean() > 0.05


def test_user_folder_is_a_fifth_kind(tmp_path):
    colours = {"a.png": (200, 30, 30), "b.jpg": (20, 120, 250)}
    for name, bgr in colours.items():
        cv2.imwrite(str(tmp_path / name), np.full((90, 200, 3), bgr[::-1], np.uint8))
    (tmp_path / "notes.txt").write_text("not an image")
    cfg = load_config(overrides={"background": {"user_dir": str(tmp_path)}})
    assert [p.rsplit("/", 1)[1] for p in cfg["background"]["user_images"]] == ["a.png", "b.jpg"]
    assert cfg["background"]["probs"]["user"] == 0.2  # the default as written: a folder leaves it alone
    specs = kind_specs("user", n=6, user_dir=str(tmp_path))
    assert {s.background.params["image"].rsplit("/", 1)[1] for s in specs} == set(colours)
    for spec in specs:
        name = spec.background.params["image"].rsplit("/", 1)[1]
        expected = srgb_to_linear(np.array(colours[name], np.float32) / 255.0)
        # a.png: lossless, and a flat image resizes to itself (uint8 weights sum to one in fixed point), so
        # the same float32 operations give the same floats. b.jpg: JPEG's DC quantisation and YCbCr roundings
        # move a flat colour by ~1 DN a channel (here (20, 120, 250) decodes as (19, 120, 250)), and a DN is
        # at most 2.2 / 255 = 0.0087 in linear (sRGB's steepest, at 250 DN); a missed sRGB decoding is ~0.3
        atol = 0.0 if name.endswith(".png") else 0.01
        assert np.allclose(background_image(spec), expected, rtol=0, atol=atol)


def test_user_share_without_a_folder_goes_to_the_other_kinds(tmp_path):
    probs = load_config()["background"]["probs"]
    assert probs["user"] == 0.0 and probs["clean"] == 0.25  # 0.2 / (1 - 0.2) rounds to 0.25 in float64
    with pytest.raises(ScgenError, match="user_dir"):
        load_config(overrides={"background": {"user_dir": str(tmp_path / "missing")}})
    with pytest.raises(ScgenError, match="holds no"):
        load_config(overrides={"background": {"user_dir": str(tmp_path)}})
