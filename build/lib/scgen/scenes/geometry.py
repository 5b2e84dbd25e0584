"""Small pure functions for rotations and pinhole projection."""

from __future__ import annotations

import numpy as np


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A rotation matrix drawn uniformly from SO(3) (normalised Gaussian quaternion)."""
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return quat_to_matrix(q)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) -> 3x3 rotation matrix."""
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def random_unit_vector(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def random_direction_in_cone(rng: np.random.Generator, axis: np.ndarray, max_angle_rad: float) -> np.ndarray:
    """A unit vector uniform over the spherical cap of half-angle `max_angle_rad` around `axis`."""
    axis = axis / np.linalg.norm(axis)
    cos_t = 1.0 - rng.uniform() * (1.0 - np.cos(max_angle_rad))
    sin_t = np.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    phi = rng.uniform(0.0, 2 * np.pi)
    u, w = orthonormal_basis(axis)
    return cos_t * axis + sin_t * (np.cos(phi) * u + np.sin(phi) * w)


def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing `n` to an orthonormal basis."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def focal_length(K: np.ndarray) -> float:
    """Mean focal length in pixels: a size s at depth z projects to about focal * s / z pixels."""
    return 0.5 * (K[0, 0] + K[1, 1])


def unit_sphere_hits(rays: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, ...]:
    """Unit rays (N x 3, from the origin) against the unit sphere at `centre`: (hit, normals, b, disc).

    Ray s * r meets the sphere at s = b -+ sqrt(disc); `hit` = disc > 0; `normals` are the outward
    unit normals at the near hits (one per hit ray); disc < 0 measures how far a ray passes outside.
    """
    b = rays @ centre
    disc = b * b - (centre @ centre - 1.0)
    hit = disc > 0
    return hit, rays[hit] * (b[hit] - np.sqrt(disc[hit]))[:, None] - centre, b, disc


def backproject(K: np.ndarray, u: float, v: float, z: float) -> np.ndarray:
    """Camera-frame point at depth z (along the optical axis) seen at pixel centre (u, v)."""
    return z * np.linalg.solve(K, np.array([u, v, 1.0]))


def project(K: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Pixel coordinates of camera-frame points X (N x 3)."""
    x = X @ K.T
    return x[:, :2] / x[:, 2:3]


def look_rotation(forward: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A rotation whose local z axis is `forward`, with a random roll about it."""
    f = forward / np.linalg.norm(forward)
    u, w = orthonormal_basis(f)
    a = rng.uniform(0, 2 * np.pi)
    x = np.cos(a) * u + np.sin(a) * w
    return np.stack([x, np.cross(f, x), f], axis=1)


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """3x3 rotation -> unit quaternion (w, x, y, z) with w >= 0 (Shepperd's method)."""
    R = np.asarray(R, dtype=np.float64)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = [0.0, 0.0, 0.0, 0.0]
        q[0] = (R[k, j] - R[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + k] = (R[k, i] + R[i, k]) / s
    q = np.asarray(q)
    return q if q[0] >= 0 else -q
