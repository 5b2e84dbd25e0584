"""The camera stage's per-image draws, from the sample's own `camera` stream (scgen.scenes.rng).

Drawn here, with every other factor, so a sample's imaging is pure data in its SceneSpec: logged in the
record and metadata, identical whatever renders it. Adding this stream shifts no other factor's draws.
"""

from __future__ import annotations

import numpy as np

from scgen.scenes.config.camera import CameraSettings, SensorSettings, preset_settings
from scgen.scenes.spec import ImagingSpec

IDEAL_IMAGING = ImagingSpec(0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 95, 0, preset_settings("ideal"))  # no draws
MID_GREY = 0.18  # the linear value at which an image's noise level is stated


def electrons_per_value(sensor: SensorSettings, gain: float) -> float:
    """Photo-electrons per unit of linear image value at analog gain `gain` (scgen.render.camera.sensor)."""
    return sensor.full_well_e / (sensor.full_well_value * gain)


def mid_grey_snr(camera: CameraSettings, gain: float) -> float | None:
    """Signal-to-noise ratio of a mid-grey pixel (shot, dark and read noise); None without a sensor."""
    sensor = camera.sensor
    if not sensor.enabled:
        return None
    signal = MID_GREY * electrons_per_value(sensor, gain)
    dark = sensor.dark_current_e_s * sensor.exposure_time_s
    return float(signal / np.sqrt(signal + dark + sensor.read_noise_e**2))


def sample_imaging(rng: np.random.Generator, camera: CameraSettings) -> ImagingSpec:
    """One image's exposure shift, noise level, PSF, motion blur, vignetting, lateral colour and JPEG
    quality, drawn in a fixed order from `rng` within the ranges of the camera's settings."""
    exposure, optics, sensor = camera.exposure, camera.optics, camera.sensor
    ev_shift = float(rng.uniform(*exposure.ev_range)) if exposure.mode == "range" else 0.0
    gain = float(np.exp(rng.uniform(*np.log(sensor.gain)))) if sensor.enabled else 1.0
    psf = float(rng.uniform(*optics.psf_fwhm_px))
    blurred = rng.uniform() < optics.motion_blur_prob
    motion = float(rng.uniform(*optics.motion_blur_px)) if blurred else 0.0
    motion_deg = float(rng.uniform(0.0, 180.0))
    vignetting = float(rng.uniform(*optics.vignetting))
    chromatic = 0.0 if camera.output.mono else float(rng.uniform(*optics.chromatic_px))
    q = camera.output.jpeg_quality
    quality = int(rng.integers(q[0], q[1] + 1))
    return ImagingSpec(
        ev_shift=ev_shift, gain=gain, psf_fwhm_px=psf, motion_blur_px=motion, motion_blur_deg=motion_deg,
        vignetting=vignetting, chromatic_px=chromatic, jpeg_quality=quality,
        noise_seed=int(rng.integers(2**31)), camera=camera,
    )  # fmt: skip
