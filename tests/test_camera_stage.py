"""The camera stage's physics: photon transfer, PSF width, blooming's charge, exposure, flare, lens.

Sensor and optics are checked on images whose truth is known (flat fields, a point source, a column of
charge); the lens on a ramp image that encodes where each render-camera pixel looks.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from scgen.errors import ScgenError
from scgen.io.buffers import TARGET_ID
from scgen.render.camera import glare, optics
from scgen.render.camera.characterise import photon_transfer
from scgen.render.camera.exposure import exposure_shift_ev, luminance
from scgen.render.camera.lens import render_camera, to_camera
from scgen.render.camera.sensor import bloom_columns, conversion_gain, expose, shot_noise
from scgen.scenes import load_config
from scgen.scenes.config.camera import camera_preset, preset_settings
from scgen.scenes.lens import distort, undistort
from scgen.scenes.spec import CameraSpec, SunSpec

SPEEDPLUS = camera_preset("speedplus")


@pytest.mark.parametrize("preset, gain", [("default", 1.0), ("default", 16.0), ("speedplus", 2.0)])
def test_photon_transfer_recovers_conversion_gain_and_read_noise(preset: str, gain: float):
    """Variance against mean over flat fields recovers the configured ADC codes per electron and read
    noise (a 16-bit ADC, so the read noise is resolved; no dark current, hot or dead pixels)."""
    sensor = replace(preset_settings(preset).sensor, adc_bits=16, dark_current_e_s=0.0, hot_pixel_frac=0.0,
                     dead_pixel_frac=0.0)  # fmt: skip
    k, read_noise = photon_transfer(sensor, gain)
    assert k == pytest.approx(conversion_gain(sensor, gain), rel=0.10)
    assert read_noise == pytest.approx(sensor.read_noise_e, rel=0.10)


@pytest.mark.parametrize("lam", [0.3, 3.0, 25.0])
def test_few_electrons_are_poisson(lam: float):
    counts = shot_noise(np.full(200_000, lam, np.float32), np.random.default_rng(1))
    assert np.array_equal(counts, np.round(counts))  # whole electrons
    assert counts.mean() == pytest.approx(lam, rel=0.02)
    assert counts.var() == pytest.approx(lam, rel=0.03)
    assert (counts == 0).mean() == pytest.approx(np.exp(-lam), abs=0.003)


@pytest.mark.parametrize("fwhm", [1.5, 2.5, 4.0])
def test_gaussian_psf_of_a_point_source_has_the_configured_fwhm(fwhm: float):
    point = np.zeros((41, 41, 1), np.float32)
    point[20, 20] = 1.0
    img = optics.psf_blur(point, "gaussian", fwhm)[..., 0]
    # float32: cv2's kernel sums to one within a few u32, numpy's pairwise sum of 41 x 41 adds ~log2(1681)
    # u32: ~1e-6, inside 1e-4, where a kernel not normalised to one is O(1) off
    assert img.sum() == pytest.approx(1.0, rel=1e-4)
    y, x = np.mgrid[0:41, 0:41] - 20
    sigma = np.sqrt((img * x**2).sum() / img.sum())
    # cv2 samples the Gaussian at pixel centres: by Poisson summation its variance is sigma^2 (1 - 8 pi^2
    # sigma^2 e^(-2 pi^2 sigma^2)), -1.1 % at fwhm 1.5 (sigma 0.64), < 1e-7 from 2.5; its cut at ~4 sigma
    # drops < 0.2 % of it, and 2.3548 is 2 sqrt(2 ln 2) to 1e-5: sigma within 0.6 %, where an area-sampled
    # kernel (+1/12 px^2) is +10 % at fwhm 1.5 and a sigma / FWHM mix-up 2.35x
    assert 2.3548 * sigma == pytest.approx(fwhm, rel=0.01)


@pytest.mark.parametrize("diameter", [3.0, 5.0, 8.0])
def test_defocus_disc_of_a_point_source_has_the_configured_width(diameter: float):
    """A uniform disc of area A peaks at 1/A (its inner pixels are wholly covered): the diameter of the
    disc of that area is the configured one."""
    point = np.zeros((41, 41, 1), np.float32)
    point[20, 20] = 1.0
    img = optics.psf_blur(point, "defocus", diameter)[..., 0]
    assert img.sum() == pytest.approx(1.0, rel=1e-4)  # k / k.sum() cast to float32 (u32 an entry); as above
    # A is a count of the 1/8 px subsamples whose centres lie in the disc (exact: sixteenths squared), 448,
    # 1264 and 3228 of 64 a px^2 against pi D^2 / 4 (-1.0, +0.6, +0.3 %): D within 0.5 % plus a few u32,
    # where a radius / diameter mix-up is 2x
    assert 2 * np.sqrt(1 / (np.pi * img.max())) == pytest.approx(diameter, rel=0.01)


def test_motion_blur_is_a_line_of_the_drawn_length_and_direction():
    point = np.zeros((41, 41, 1), np.float32)
    point[20, 20] = 1.0
    img = optics.motion_blur(point, 10.0, 0.0)[..., 0]
    assert img.sum() == pytest.approx(1.0, rel=1e-4)
    assert np.abs(img[:19]).sum() + np.abs(img[22:]).sum() < 1e-6  # horizontal: no light off the row
    xs = np.nonzero(img.sum(axis=0) > 1e-4)[0]
    assert xs.max() - xs.min() + 1 == pytest.approx(11, abs=1)


def test_blooming_spills_along_columns_and_conserves_charge():
    full_well = 1000.0
    e = np.full((300, 40, 1), 100.0, np.float32)
    e[140:143, 18:21] = 40 * full_well  # 3 x 3 pixels with 39 wells of excess each
    out = bloom_columns(e, full_well)
    assert out.max() <= full_well + 1e-3
    assert out.sum() == pytest.approx(e.sum(), rel=0.05)
    assert np.array_equal(out[:, :18], e[:, :18]) and np.array_equal(out[:, 21:], e[:, 21:])  # columns only
    filled = (out[:, 18:21, 0] >= full_well - 1e-3).sum(axis=0)
    assert (filled >= 3 * 39).all()  # each column's excess filled ~39 wells' worth of pixels


def test_auto_exposure_brings_the_visible_target_to_its_target_value():
    exposure = replace(preset_settings("default").exposure, mode="auto")
    img = np.full((20, 20, 3), 0.01, np.float32)
    img[5:15, 5:15] = [0.6, 0.7, 0.8]
    visible = np.zeros((20, 20), bool)
    visible[5:15, 5:15] = True
    ev = exposure_shift_ev(exposure, 0.0, img, visible)
    shown = img * 2.0 ** (-ev)
    # float32: two means of 100 equal luminances (pairwise sums, ~7 u32 each), two 3-term luminances (~3 u32
    # each) and the scaling (u32), log2 and 2^x in float64: ~20 u32 = 1.2e-6, inside 1e-5; a wrong EV is O(1)
    assert luminance(shown)[visible].mean() == pytest.approx(exposure.auto_target, rel=1e-5)


@pytest.mark.parametrize("mode", ["range", "auto"])
def test_highlight_protection_shortens_the_exposure_just_enough_that_at_most_the_limit_clips(mode: str):
    """A frame whose bright tenth (an Earth under a strong sun) would clip: the exposure is shortened until
    at most `max_clipped` of its pixels clip, and no further (a hundredth of an EV less clips more)."""
    exposure = replace(preset_settings("default").exposure, mode=mode)
    rng = np.random.default_rng(3)
    img = rng.uniform(0.05, 0.4, (120, 160, 3)).astype(np.float32)
    img[:12] = rng.uniform(1.5, 4.0, (12, 160, 3))  # 10 % of the frame, up to 2 EV over
    visible = np.zeros((120, 160), bool)
    visible[50:70, 70:90] = True

    def clipped(ev: float) -> float:
        return float(((img * 2.0 ** (-ev)).max(axis=-1) >= 1.0).mean())

    ev = exposure_shift_ev(exposure, 0.0, img, visible)
    assert clipped(ev) <= exposure.max_clipped < clipped(ev - 0.01)
    dim = np.full_like(img, 0.05)  # nothing clips at the metered or drawn exposure: it stands
    assert exposure_shift_ev(exposure, 0.3, dim, visible) == exposure_shift_ev(
        replace(exposure, max_clipped=1.0), 0.3, dim, visible
    )
    assert exposure_shift_ev(replace(exposure, mode="fixed"), 0.0, img, visible) == 0.0  # fixed: as set


@pytest.mark.parametrize("preset", ["default", "ccd"])
def test_a_saturated_disc_stays_a_disc_on_the_default_sensor_and_spills_along_columns_on_the_ccd(preset: str):
    """The default camera's sensor drains charge above the full well (anti-blooming): only the disc
    saturates. The CCD preset's wells spill along their columns: straight streaks above and below the
    disc, exactly as wide as it, conserving the charge up to the sensor's edges."""
    camera = preset_settings(preset)
    sensor = replace(camera.sensor, hot_pixel_frac=0.0, dead_pixel_frac=0.0)
    value = np.full((200, 120, 1), 0.1, np.float32)
    y, x = np.mgrid[0:200, 0:120]
    disc = (y - 100) ** 2 + (x - 60) ** 2 <= 6**2
    value[disc] = 30.0  # 30 wells of charge per disc pixel
    out = expose(value, sensor, 1.0, camera.glare.blooming, 0, np.random.default_rng(0))[..., 0]
    saturated = out > 0.99  # a full well reads the top code give or take its read noise
    if preset == "default":
        assert np.array_equal(saturated, disc)
        return
    columns = np.nonzero(disc.any(axis=0))[0]
    assert not saturated[:, : columns[0]].any() and not saturated[:, columns[-1] + 1 :].any()
    streak = saturated[:, columns].sum(axis=0)
    assert (streak > 3 * disc[:, columns].sum(axis=0)).all()  # each column well past the disc's chord


def test_lens_round_trip_is_exact():
    xy = np.random.default_rng(0).uniform(-0.35, 0.35, (1000, 2))
    back = undistort(distort(xy, tuple(SPEEDPLUS["dist"])), tuple(SPEEDPLUS["dist"]))
    # Newton stops once distort(back) is within NEWTON_TOL = 1e-13 of the target (float64's floor is a few
    # u64); the lens' Jacobian over |x|, |y| <= 0.35 has singular values >= 0.95, so back is within 1.1e-13
    # of xy, where a wrong inverse is off by the distortion itself (~1e-2)
    assert np.abs(back - xy).max() < 1e-12


def test_speedplus_distortion_moves_edge_pixels_as_published():
    """SPEED+'s lens moves the middle of the right edge by ~17 px and the corner by ~25 px."""
    cfg = load_config(camera="speedplus")
    cam = CameraSpec.from_config(cfg["camera"])
    pinhole = replace(cam, dist=())
    for (u, v), shift in (((1919.0, 600.0), 17.0), ((1919.0, 1199.0), 25.0)):
        ideal = pinhole.rays(np.array([u]), np.array([v]))
        moved = cam.project(ideal)[0]
        # the shifts are stated to the whole pixel (docs/scgen.md); the model's own, in float64 (~1e-10 px),
        # are 17.21 and 25.43 px, so within the rounding's 0.5 px
        assert np.hypot(moved[0] - u, moved[1] - v) == pytest.approx(shift, abs=0.5)


def test_render_camera_resampling_lands_each_pixel_on_its_ray():
    """A ramp image on the render camera holds, at each pixel, that pixel's own coordinates; resampled
    through the lens, pixel p must hold the render-camera projection of p's ray (bilinear is exact on a
    ramp, up to cv2.remap's 1/32 px interpolation grid)."""
    cfg = load_config(camera="speedplus", resolution=(240, 150))
    cam = CameraSpec.from_config(cfg["camera"])
    shown = render_camera(cam)
    assert shown.K_mat[0, 0] == shown.K_mat[1, 1] and shown.pinhole
    v, u = np.mgrid[0 : shown.height, 0 : shown.width].astype(np.float32)
    ramp = np.stack([u, v, np.zeros_like(u)], axis=-1)
    got = to_camera(ramp, cam)[..., :2]
    rays = cam.pixel_rays()
    want = np.stack([rays[..., 0], rays[..., 1]], -1) * shown.K_mat[0, 0] + shown.K_mat[:2, 2]
    assert np.abs(got - want).max() < 1 / 32 + 1e-3


def _spec_with_sun(direction: tuple[float, float, float]):
    from scgen.generator import Generator

    gen = Generator.load(seed=1, resolution=(160, 120), backend="mitsuba")
    spec = gen.scene(0)
    return replace(spec, sun=SunSpec(direction, "normal", 1361.0))


def test_sun_in_view_flares_over_the_image_unless_the_target_hides_it():
    s = np.array([0.05, -0.03, 1.0])
    spec = _spec_with_sun(tuple(s / np.linalg.norm(s)))
    img = np.zeros((120, 160, 3), np.float32)
    rng = np.random.default_rng(0)
    clear = np.zeros((120, 160), np.int32)
    flared, present = glare.sun_flare(img, spec, clear, 0.0, spec.imaging.camera.glare, rng)
    assert present and flared.min() > 0  # veiling glare over every pixel
    assert flared.max() > 1e3  # the sun's disc itself
    hidden = np.full((120, 160), TARGET_ID, np.int32)
    dark, present = glare.sun_flare(img, spec, hidden, 0.0, spec.imaging.camera.glare, rng)
    assert not present and dark.max() == 0.0


def test_sun_behind_the_camera_never_flares():
    spec = _spec_with_sun((0.0, 0.0, -1.0))
    img = np.zeros((120, 160, 3), np.float32)
    out, present = glare.sun_flare(img, spec, np.zeros((120, 160), np.int32), 0.0,
                                   spec.imaging.camera.glare, np.random.default_rng(0))  # fmt: skip
    assert not present and out is img


def test_bloom_spreads_only_light_above_saturation():
    img = np.full((64, 64, 1), 0.5, np.float32)
    assert glare.bloom(img, 0.1, 40.0, 6) is img
    img[32, 32] = 5000.0
    out = glare.bloom(img, 0.1, 40.0, 6)
    assert out[32, 40, 0] > 0.5 and out[0, 0, 0] >= 0.5
    halo = (out - img).sum()
    assert halo == pytest.approx(0.1 * (5000.0 - 1.0), rel=0.1)  # the share of the excess, spread


@pytest.mark.parametrize(
    "override, message",
    [
        ({"camera": {"output": {"bits": 12}}}, "camera.output.bits"),
        ({"camera": {"optics": {"psf_fwhm_px": [2.0, 1.0]}}}, "camera.optics.psf_fwhm_px"),
        ({"camera": {"dist": [0.1, 0.2]}}, "camera.dist"),
        ({"camera": {"exposure": {"mode": "manual"}}}, "camera.exposure.mode"),
    ],
)
def test_bad_camera_values_are_named(override: dict, message: str):
    with pytest.raises(ScgenError, match=message):
        load_config(overrides=override)


def test_unknown_preset_is_named():
    with pytest.raises(ScgenError, match="unknown camera preset 'gopro'"):
        load_config(camera="gopro")
