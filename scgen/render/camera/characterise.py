"""Measure a sensor model as one measures a camera (EMVA 1288's photon transfer), from its own output."""

from __future__ import annotations

import numpy as np

from scgen.render.camera.sensor import expose
from scgen.scenes.config.camera import SensorSettings
from scgen.scenes.imaging import electrons_per_value

PTC_STEPS = 10


def photon_transfer(sensor: SensorSettings, gain: float, size: int = 128) -> tuple[float, float]:
    """(conversion gain in codes per e-, read noise in e-) fitted to var = K * mean + K^2 * sigma^2 over
    flat fields from a few tens of electrons to half the ADC's range. Two frames per level, differenced,
    so the fixed pattern (PRNU) cancels; relative weights, as photon-transfer curves are fitted; the
    codes' 1/12 quantisation variance removed."""
    top = 2**sensor.adc_bits - 1
    lowest_e = max(20.0, 3 * sensor.read_noise_e**2)  # the noise floor a quarter of the variance or less
    lowest = min(lowest_e / electrons_per_value(sensor, gain), 0.05)  # ...and nothing clips at zero
    means, variances = [], []
    for k, level in enumerate(np.geomspace(lowest, 0.5, PTC_STEPS)):
        flat = np.full((size, size, 1), level, np.float32)
        a, b = (expose(flat, sensor, gain, True, 0, np.random.default_rng([k, j])) * top for j in (1, 2))
        means.append(0.5 * (a.mean() + b.mean()))
        variances.append(np.var(a.astype(np.float64) - b) / 2)
    slope, intercept = np.polyfit(means, variances, 1, w=1 / np.asarray(variances))
    return float(slope), float(np.sqrt(max(intercept - 1 / 12, 0.0)) / slope)
