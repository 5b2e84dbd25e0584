"""Per-factor random streams: each factor of each sample draws from its own generator.

The stream is keyed by (seed, sample index, factor name), so changing one factor's
distribution never shifts the random numbers any other factor sees.
"""

from __future__ import annotations

import zlib

import numpy as np

FACTORS = (
    "pose", "distance", "position", "illumination", "shadow", "background", "occluders", "camera",
    "sky", "finish", "sun_view",
)  # fmt: skip


def factor_rng(seed: int, index: int, factor: str) -> np.random.Generator:
    """A generator that depends only on (seed, index, factor)."""
    if factor not in FACTORS:
        raise ValueError(f"unknown factor stream {factor!r}")
    return np.random.default_rng([int(seed), int(index), zlib.crc32(factor.encode())])
