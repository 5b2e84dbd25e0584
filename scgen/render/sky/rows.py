"""Row-wise dot products and norms of N x 3 arrays, bit for bit numpy's `np.sum(a * b, axis=1)` and
`np.linalg.norm(a, axis=1)` (both add a row as (x + y) + z), about four times faster: numpy's reduction
over a last axis of three is slow."""

from __future__ import annotations

import numpy as np


def row_dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """np.sum(a * b, axis=1) of N x 3 arrays (b may be one 3-vector)."""
    p = a * b
    return (p[:, 0] + p[:, 1]) + p[:, 2]


def row_norm(a: np.ndarray) -> np.ndarray:
    """np.linalg.norm(a, axis=1) of an N x 3 array."""
    return np.sqrt(row_dot(a, a))
