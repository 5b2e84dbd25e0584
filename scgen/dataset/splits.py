"""Train/val/test planning by factor combinations (paper §4.1) or at random, before rendering.

The split of every index is known up front from the SceneSpecs alone, so sharded, parallel and
resumed runs agree. With `factors`, each sample gets a combination key from discretised scene
factors and whole combinations go to one split: the test set holds configurations never seen in
training. Keys come only from values stored in metadata.csv, so they can be re-derived and checked.
"""

from __future__ import annotations

import hashlib
from collections import defaultdict
from collections.abc import Iterable, Sequence

import numpy as np

from scgen.errors import ScgenError

SPLITS = ("train", "val", "test")
DEFAULT_RATIOS = (0.7, 0.1, 0.2)


def parse_ratios(text: str | Sequence[float]) -> tuple[float, float, float]:
    """'0.7,0.1,0.2' -> (0.7, 0.1, 0.2); they must be three non-negative numbers summing to 1."""
    try:
        values = [float(x) for x in (text.split(",") if isinstance(text, str) else text)]
    except ValueError as exc:
        raise ScgenError(f"split ratios must be numbers, got '{text}'") from exc
    if len(values) != 3 or not all(0 <= v <= 1 for v in values) or not abs(sum(values) - 1.0) <= 1e-6:
        raise ScgenError(f"split ratios must be three non-negative numbers summing to 1, got '{text}'")
    return values[0], values[1], values[2]


def _stable_hash(seed: int, text: str) -> int:
    return int.from_bytes(hashlib.sha256(f"{seed}:{text}".encode()).digest()[:8], "big")


def plan_splits(keys: Sequence[str], ratios: Sequence[float], seed: int, mode: str = "factors") -> list[str]:
    """The split name of every sample index (len(keys) samples)."""
    n = len(keys)
    targets = np.asarray(ratios, float) * n
    if mode == "random":
        order = sorted(range(n), key=lambda i: _stable_hash(seed, f"sample{i}"))
        bounds = np.round(np.cumsum(targets)).astype(int)
        split_of = [""] * n
        for rank, i in enumerate(order):
            split_of[i] = SPLITS[int(np.searchsorted(bounds, rank, side="right"))]
        return split_of
    if mode != "factors":
        raise ScgenError(f"unknown split mode '{mode}' (choose factors or random)")
    groups: dict[str, list[int]] = defaultdict(list)
    for i, key in enumerate(keys):
        groups[key].append(i)
    counts = np.zeros(3)
    split_of = [""] * n
    # largest combinations first, ties in a seeded random order; each goes where the deficit is largest
    order = sorted(groups, key=lambda k: (-len(groups[k]), _stable_hash(seed, k)))
    for key in order:
        deficit = (targets - counts) / np.maximum(targets, 1e-9)
        s = int(np.argmax(np.where(targets > 0, deficit, -np.inf)))
        for i in groups[key]:
            split_of[i] = SPLITS[s]
        counts[s] += len(groups[key])
    return split_of


def leakage(keys: Sequence[str], split_of: Sequence[str]) -> dict[str, int]:
    """Number of combination keys shared by each pair of splits (0 everywhere for a factor split)."""
    sets = {s: {k for k, sp in zip(keys, split_of, strict=True) if sp == s} for s in SPLITS}
    return {
        f"{a}-{b}": len(sets[a] & sets[b]) for a, b in (("train", "val"), ("train", "test"), ("val", "test"))
    }


def split_lists(split_of: Iterable[str]) -> dict[str, list[int]]:
    out: dict[str, list[int]] = {s: [] for s in SPLITS}
    for i, s in enumerate(split_of):
        out[s].append(i)
    return out
