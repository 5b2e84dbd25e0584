"""Rotations for the filter: the skew matrix, the exponential and logarithm maps of SO(3).

Rotation vectors are in radians; `exp(a)` is the rotation by |a| about a / |a| (scipy's from_rotvec) and
`log` its inverse on [0, pi]. Pure numpy/scipy.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def skew(v: np.ndarray) -> np.ndarray:
    """[v]x: skew(v) @ u == cross(v, u)."""
    x, y, z = np.asarray(v, np.float64)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def exp(a: np.ndarray) -> np.ndarray:
    """The rotation matrix of rotation vector `a` (..., 3) -> (..., 3, 3)."""
    a = np.asarray(a, np.float64)
    return Rotation.from_rotvec(a.reshape(-1, 3)).as_matrix().reshape(a.shape[:-1] + (3, 3))


def log(R: np.ndarray) -> np.ndarray:
    """The rotation vector of rotation matrix `R` (..., 3, 3) -> (..., 3), angle in [0, pi]."""
    R = np.asarray(R, np.float64)
    return Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(R.shape[:-2] + (3,))


def angle_deg(R: np.ndarray) -> np.ndarray:
    """The angle of rotation matrices (..., 3, 3), in degrees."""
    return np.degrees(np.linalg.norm(log(R), axis=-1))
