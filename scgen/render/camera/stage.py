"""The camera stage: a backend's linear HDR composite -> the image a real camera would record.

In order: the lens' resampling (distortion, non-square pixels), the exposure, a monochrome sensor's
luminance, the sun's disc, veiling glare and ghosts, vignetting, lateral colour, the PSF, motion blur,
bloom of over-exposed light, then the sensor (photo-electrons, fixed pattern, shot/dark/read noise,
blooming, ADC) and the output curve. Its random numbers come from the sample's `camera` stream
(SceneSpec.imaging), so the labels never depend on it.
"""

from __future__ import annotations

import numpy as np

from scgen.io.buffers import TARGET_ID, CameraRecord
from scgen.render.camera import glare, optics
from scgen.render.camera.exposure import exposure_shift_ev, luminance
from scgen.render.camera.lens import to_camera
from scgen.render.camera.output import encode, encode_codes, saturated_code
from scgen.render.camera.sensor import expose_codes
from scgen.scenes.imaging import IDEAL_IMAGING
from scgen.scenes.spec import SceneSpec


def record_image(
    spec: SceneSpec, composite: np.ndarray, instance: np.ndarray
) -> tuple[np.ndarray, CameraRecord]:
    """The recorded image (uint8/uint16, H x W x 3 or H x W) of a linear composite rendered on
    render_camera(spec.camera), and what the stage decided. `instance`: the camera's instance ids."""
    imaging = spec.imaging or IDEAL_IMAGING
    cam = imaging.camera
    image = to_camera(composite.astype(np.float32, copy=False), spec.camera)
    shift = exposure_shift_ev(cam.exposure, imaging.ev_shift, image, instance == TARGET_ID)
    if shift:
        image = image * np.float32(2.0 ** (-shift))
    if cam.output.mono:
        image = luminance(image)[..., None]
    rng = np.random.default_rng([imaging.noise_seed, spec.index])
    ev_total = spec.camera.exposure_ev + shift
    image, flared = glare.sun_flare(image, spec, instance, ev_total, cam.glare, rng)
    image = optics.vignette(image, spec.camera, imaging.vignetting)
    image = optics.lateral_colour(image, spec.camera, imaging.chromatic_px)
    image = optics.psf_blur(image, cam.optics.psf, imaging.psf_fwhm_px)
    image = optics.motion_blur(image, imaging.motion_blur_px, imaging.motion_blur_deg)
    g = cam.glare
    image = glare.bloom(image, g.bloom, g.bloom_radius_px, g.spikes)
    out = cam.output
    if cam.sensor.enabled:  # the ADC's codes to the file's by table (the same pixels as encode(expose))
        codes = expose_codes(image, cam.sensor, imaging.gain, g.blooming, spec.seed, rng)
        saturated = float(np.count_nonzero(codes >= saturated_code(cam.sensor.adc_bits)) / codes.size)
        pixels = encode_codes(codes, cam.sensor.adc_bits, out.curve, out.bits)
        return pixels, CameraRecord(float(ev_total), flared, saturated)
    saturated = float((image >= 1.0).mean())
    pixels = encode(image, out.curve, out.bits)
    return pixels, CameraRecord(float(ev_total), flared, saturated)
