"""OpenCV's 5-coefficient lens distortion (k1, k2, p1, p2, k3) on normalised image coordinates.

Pure functions. `distort` is OpenCV's forward model (what cv2.projectPoints applies); `undistort`
inverts it by Newton's method to machine precision, because the label maps are exact per pixel and
cv2.undistortPoints' fixed-point iteration leaves ~1e-4 px behind on strong lenses.
"""

from __future__ import annotations

import numpy as np

NEWTON_STEPS = 30
NEWTON_TOL = 1e-13  # normalised units: ~1e-10 px at fx 3000


def distort(xy: np.ndarray, dist: tuple[float, ...]) -> np.ndarray:
    """Distorted normalised coordinates of ideal ones (..., 2): OpenCV's model."""
    k1, k2, p1, p2, k3 = dist
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([xd, yd], axis=-1)


def _jacobian(x: np.ndarray, y: np.ndarray, dist: tuple[float, ...]) -> tuple[np.ndarray, ...]:
    """d(xd, yd)/d(x, y) of `distort` at (x, y): the four entries."""
    k1, k2, p1, p2, k3 = dist
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    d_radial = k1 + r2 * (2 * k2 + 3 * k3 * r2)  # d radial / d r2
    dxx = radial + 2 * x * x * d_radial + 2 * p1 * y + 6 * p2 * x
    dxy = 2 * x * y * d_radial + 2 * p1 * x + 2 * p2 * y
    dyx = 2 * x * y * d_radial + 2 * p1 * x + 2 * p2 * y
    dyy = radial + 2 * y * y * d_radial + 6 * p1 * y + 2 * p2 * x
    return dxx, dxy, dyx, dyy


def undistort(xy_d: np.ndarray, dist: tuple[float, ...]) -> np.ndarray:
    """Ideal normalised coordinates whose distortion is `xy_d` (..., 2), by Newton's method."""
    xy = np.array(xy_d, dtype=np.float64, copy=True)
    for _ in range(NEWTON_STEPS):
        residual = distort(xy, dist) - xy_d
        if np.abs(residual).max(initial=0.0) < NEWTON_TOL:
            break
        dxx, dxy, dyx, dyy = _jacobian(xy[..., 0], xy[..., 1], dist)
        det = dxx * dyy - dxy * dyx
        xy[..., 0] -= (dyy * residual[..., 0] - dxy * residual[..., 1]) / det
        xy[..., 1] -= (dxx * residual[..., 1] - dyx * residual[..., 0]) / det
    return xy


def is_pinhole(dist: tuple[float, ...]) -> bool:
    """No distortion: absent or all coefficients zero."""
    return not any(dist)
