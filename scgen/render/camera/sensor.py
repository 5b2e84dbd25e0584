"""The image sensor: photo-electrons, shot/dark/read noise, fixed pattern, blooming, ADC.

Radiometry (scgen.render.lighting): image value 1.0 is a white plate under the 1-AU sun at EV 0. At
analog gain g, value v collects v * full_well_e / (full_well_value * g) electrons, so a higher gain
(the drawn noise level) gives the same brightness from fewer photons. The ADC maps value 1.0 to its
largest code: at g > 1 it clips before the well fills; charge beyond the well blooms along columns.
"""

from __future__ import annotations

import functools

import numpy as np

from scgen.scenes.config.camera import SensorSettings
from scgen.scenes.imaging import electrons_per_value

POISSON_EXACT_BELOW = 30.0  # mean electrons; above it the normal approximation (same mean and variance)


def conversion_gain(sensor: SensorSettings, gain: float) -> float:
    """ADC codes per electron at this gain (the photon-transfer slope)."""
    return (2**sensor.adc_bits - 1) / electrons_per_value(sensor, gain)


@functools.lru_cache(maxsize=4)
def fixed_pattern(seed: int, shape: tuple[int, ...], prnu: float, hot_frac: float,
                  dead_frac: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """(PRNU gain map, hot pixels, dead pixels) of the dataset's one camera, fixed by its seed."""
    rng = np.random.default_rng([int(seed), 0x5E4502])
    response = (1.0 + prnu * rng.standard_normal(shape, dtype=np.float32)).clip(0, None)
    hot = rng.random(shape[:2], dtype=np.float32) < hot_frac
    dead = rng.random(shape[:2], dtype=np.float32) < dead_frac
    return response, hot, dead


@functools.lru_cache(maxsize=4)
def pattern_pixels(seed: int, shape: tuple[int, ...], prnu: float, hot_frac: float,
                   dead_frac: float) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:  # fmt: skip
    """fixed_pattern's hot and dead pixels as (row, column) indices: cheaper to index by than the masks."""
    _, hot, dead = fixed_pattern(seed, shape, prnu, hot_frac, dead_frac)
    return np.nonzero(hot), np.nonzero(dead)


def shot_noise(mean_e: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Poisson electron counts of these means: exact below POISSON_EXACT_BELOW (inverse CDF), normal
    above. Every pixel takes one uniform and one normal draw, so a pixel's noise never depends on how
    bright the other pixels are (a renderer's last-bit differences cannot reshuffle the noise)."""
    u = rng.random(mean_e.shape, dtype=np.float32)
    out = rng.standard_normal(mean_e.shape, dtype=np.float32)
    out *= np.sqrt(mean_e)
    out += mean_e  # mean_e + sqrt(mean_e) * normal, in place
    low = mean_e < POISSON_EXACT_BELOW
    out[low] = poisson_quantile(mean_e[low], u[low])
    return out


POISSON_BLOCK = 8  # steps between two compactions of poisson_quantile's draws still summing


def poisson_quantile(lam: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The smallest k with P(X <= k) >= u for X ~ Poisson(lam), elementwise (1-D, lam below ~80).

    The CDF is summed term by term for the draws still above it. A draw, once at or below its CDF (or
    with its term underflowed to 0), stays so, so its k is the number of steps it was above it: the
    steps run in blocks over the draws left (POISSON_BLOCK of them, 1 for the first two, where most
    stop), which are compacted only between blocks. Each draw sees the same float32 operations in the
    same order as when summed one step at a time."""
    k = np.zeros(lam.shape, np.float32)
    term = np.exp(-lam)
    idx = np.nonzero(u > term)[0]
    lam, u, term = lam[idx], u[idx], term[idx]
    cdf = term.copy()
    count = np.ones(idx.size, np.float32)
    alive, positive = np.empty(idx.size, bool), np.empty(idx.size, bool)
    step = 1
    while idx.size:
        for _ in range(1 if step < 3 else POISSON_BLOCK):
            term *= lam / step
            cdf += term
            np.greater(u, cdf, out=alive)
            np.greater(term, 0, out=positive)
            alive &= positive
            count += alive
            step += 1
        done = ~alive
        k[idx[done]] = count[done]
        idx, lam, u, term, cdf, count = (a[alive] for a in (idx, lam, u, term, cdf, count))
        alive, positive = alive[: idx.size], positive[: idx.size]
    return k


def bloom_columns(electrons: np.ndarray, full_well: float) -> np.ndarray:
    """Charge above the full well spills along its column, half each way, filling neighbours up to the
    well; what reaches the sensor's top or bottom edge drains away. Conserves charge otherwise."""
    over = np.maximum(electrons - full_well, 0.0)
    columns = over.reshape(over.shape[0], -1).any(axis=0)
    if not columns.any():
        return electrons
    h = electrons.shape[0]
    flat = electrons.reshape(h, -1)
    e = np.minimum(flat[:, columns], full_well).astype(np.float64)
    spill = over.reshape(h, -1)[:, columns].astype(np.float64) / 2
    rows = np.nonzero(spill.any(axis=1))[0]
    for order in (range(rows[0], h), range(rows[-1], -1, -1)):  # down, then up
        carry = np.zeros(e.shape[1])
        for y in order:
            carry += spill[y]
            take = np.minimum(full_well - e[y], carry)
            e[y] += take
            carry -= take
            if not carry.any() and (y > rows[-1] if order.step > 0 else y < rows[0]):
                break
    out = flat.copy()
    out[:, columns] = e
    return out.reshape(electrons.shape)


def expose(value: np.ndarray, sensor: SensorSettings, gain: float, blooming: bool, seed: int,
           rng: np.random.Generator) -> np.ndarray:  # fmt: skip
    """The sensor's reading of a linear image (H x W x C, exposure applied), as linear values in [0, 1]
    quantised to the ADC's codes."""
    codes = expose_codes(value, sensor, gain, blooming, seed, rng)
    return (codes / np.float32(2**sensor.adc_bits - 1)).astype(np.float32)


def expose_codes(value: np.ndarray, sensor: SensorSettings, gain: float, blooming: bool, seed: int,
                 rng: np.random.Generator) -> np.ndarray:  # fmt: skip
    """expose's ADC codes (H x W x C, float32 whole numbers 0 .. 2^adc_bits - 1): expose is codes / top."""
    e_per_value = electrons_per_value(sensor, gain)
    pattern = (seed, value.shape, sensor.prnu, sensor.hot_pixel_frac, sensor.dead_pixel_frac)
    response = fixed_pattern(*pattern)[0]
    hot, dead = pattern_pixels(*pattern)
    t, top = sensor.exposure_time_s, 2**sensor.adc_bits - 1
    mean_e = np.maximum(value, 0.0)
    mean_e *= e_per_value * response
    mean_e += sensor.dark_current_e_s * t
    mean_e[hot] += sensor.hot_pixel_e_s * t
    mean_e[dead] = 0.0
    electrons = shot_noise(mean_e.astype(np.float32, copy=False), rng)
    if blooming:
        electrons = bloom_columns(electrons, sensor.full_well_e)
    np.minimum(electrons, sensor.full_well_e, out=electrons)
    read = rng.standard_normal(electrons.shape, dtype=np.float32)
    read *= sensor.read_noise_e
    electrons += read
    electrons *= top / e_per_value
    codes = np.round(electrons, out=electrons)
    return np.clip(codes, 0, top, out=codes)
