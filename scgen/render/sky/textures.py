"""Procedural texture primitives shared by the backgrounds: fractal noise and equirectangular look-ups."""

from __future__ import annotations

import numpy as np


def periodic_noise(rng: np.random.Generator, h: int, w: int, beta: float, aspect: float = 1.0) -> np.ndarray:
    """Fractal noise with power spectrum 1/f^beta, periodic in both axes (FFT-filtered white noise).

    Normalised to zero mean, unit standard deviation. `aspect` > 1 stretches features along x
    (cloud bands). Periodic in x, so an equirectangular map of it has no seam at the date line.
    """
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.rfftfreq(w)[None, :] * (h / w) * aspect
    f = np.hypot(fx, fy)
    f[0, 0] = 1.0
    spectrum = np.fft.rfft2(rng.normal(size=(h, w))) / f ** (0.5 * beta)
    spectrum[0, 0] = 0.0
    out = np.fft.irfft2(spectrum, s=(h, w))
    return (out / out.std()).astype(np.float32)


def lat_lon(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Latitude and longitude (rad) of unit vectors q (N x 3) in a frame whose z is the pole."""
    return np.arcsin(np.clip(q[:, 2], -1, 1)), np.arctan2(q[:, 1], q[:, 0])


def equirect(texture: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Bilinear look-up of an equirectangular map (rows: latitude +90..-90) at unit vectors q (N x 3)."""
    return equirect_at(texture, *lat_lon(q))


def equirect_at(texture: np.ndarray, lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """Bilinear look-up of a float32 equirectangular map (H x W, or H x W x C for C maps at once: N x C)
    at latitudes and longitudes (rad; lat_lon's), in float32."""
    h, w = texture.shape[:2]
    x = (lon / (2 * np.pi) + 0.5) * w - 0.5
    y = np.clip((0.5 - lat / np.pi) * (h - 1), 0, h - 1)
    x0, y0 = np.floor(x).astype(np.int64), np.minimum(np.floor(y).astype(np.int64), h - 2)
    fx, fy = (x - x0).astype(np.float32), (y - y0).astype(np.float32)
    if texture.ndim == 3:
        fx, fy = fx[:, None], fy[:, None]
    x0, x1 = x0 % w, (x0 + 1) % w  # wraps at the date line
    flat = texture.reshape(h * w, *texture.shape[2:])
    row = y0 * w
    top = (1 - fx) * flat.take(row + x0, axis=0) + fx * flat.take(row + x1, axis=0)
    row += w
    bottom = (1 - fx) * flat.take(row + x0, axis=0) + fx * flat.take(row + x1, axis=0)
    return (1 - fy) * top + fy * bottom
