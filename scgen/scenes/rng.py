"""Per-factor random streams: each factor of each sample draws from its own generator.

The stream is keyed by (seed, sample index, factor name), so changing one factor's
distribution never shifts the random numbers any other factor sees.
"""

from __future__ import annotations

import zlib

import numpy as np

FACTORS = (
    "pose", "distance", "position", "illumination", "shadow", "background", "occluders", "camera",
    "sky", "finish", "sun_view", "objects",
)  # fmt: skip


def factor_rng(seed: int, index: int, factor: str) -> np.random.Generator:
    """A generator that depends only on (seed, index, factor)."""
    if factor not in FACTORS:
        raise ValueError(f"unknown factor stream {factor!r}")
    return np.random.default_rng([int(seed), int(index), zlib.crc32(factor.encode())])


SEQUENCE_PARTS = (
    "orbit", "profile", "attitude", "sun", "pointing", "camera", "background", "finish", "sky", "pose",
    "objects",
)  # fmt: skip
_SEQUENCE_TAG = zlib.crc32(b"sequence")


def sequence_rng(seed: int, sequence: int, part: str) -> np.random.Generator:
    """A generator that depends only on (seed, sequence, part): a rendezvous sequence's own draws, in a
    key space apart from the samples' (four words, not three), so sequence s never shares a stream with
    sample s."""
    if part not in SEQUENCE_PARTS:
        raise ValueError(f"unknown sequence stream {part!r}")
    return np.random.default_rng([int(seed), int(sequence), _SEQUENCE_TAG, zlib.crc32(part.encode())])


def choice(rng: np.random.Generator, probs: dict[str, float]) -> str:
    """One of `probs`' names, drawn with their weights (normalised here)."""
    names = list(probs)
    p = np.array([probs[n] for n in names], dtype=float)
    return names[int(rng.choice(len(names), p=p / p.sum()))]
