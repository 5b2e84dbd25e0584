"""Dr.Jit memory the Mitsuba backend writes in place from sample to sample, and how it must be laid out.

Why: a frozen recording (drjit.freeze) is replayed by its inputs' layout, and reads the memory of what it
recorded. A value set the usual way (a new array through mi.traverse, then parameters_changed) costs a
kernel launch or more each (an opaque scalar is one memset; a mesh's new positions, thirteen launches for
its bounding box), and new buffers of a mesh are not seen by a replay at all. So a worker gives every
value it changes per sample memory of its own once, and from then on writes that memory from numpy.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import drjit as dr
import mitsuba as mi
import numpy as np

ALIGNMENT = 64  # bytes: the widest vector loads of Dr.Jit's LLVM backend (AVX-512)


def aligned_empty(shape: tuple[int, ...], dtype: type) -> np.ndarray:
    """An uninitialised array whose memory starts on a 64-byte boundary. Dr.Jit takes numpy's memory as it
    is, and notes whether it is aligned: a frozen render takes a change of that note for new inputs and
    records again, and numpy's allocations fall on 16-byte boundaries, so the note would change."""
    n, size = int(np.prod(shape)), np.dtype(dtype).itemsize
    buffer = np.empty(n * size + ALIGNMENT, np.uint8)
    start = -buffer.ctypes.data % ALIGNMENT
    return buffer[start : start + n * size].view(dtype).reshape(shape)


def aligned(values: np.ndarray) -> np.ndarray:
    """A copy of `values` in memory from aligned_empty."""
    out = aligned_empty(values.shape, values.dtype)
    out[...] = values
    return out


def own_scalars(values: Iterable[float]) -> list[mi.Float]:
    """Each value as a Float of width one in memory of its own. A literal would be shared with every equal
    literal alive (and made opaque, its memory too), so writing it in place would change them all."""
    arrays = [dr.opaque(mi.Float, float(v)) for v in values]
    check_distinct(arrays)
    return arrays


def channels(value: Any) -> list[Any]:
    """A Float parameter as a list of itself, or a Color3f's three channels."""
    return [value[c] for c in range(3)] if isinstance(value, mi.Color3f) else [value]


def check_held(given: list[Any], held: list[Any], owner: str) -> None:
    """Raise unless `held` (read back from a fresh mi.traverse of the owner) are the very arrays `given`
    it: had Mitsuba copied them, writing the given ones in place would change nothing it renders."""
    if [a.index for a in held] != [a.index for a in given]:
        raise RuntimeError(f"Mitsuba's {owner} holds copies of the arrays given, not the arrays")


def check_distinct(arrays: list[Any]) -> None:
    """Raise unless these Dr.Jit arrays are distinct variables: one memory written for two values would
    set both."""
    indices = [a.index for a in arrays]
    if len(set(indices)) != len(indices):
        raise RuntimeError(f"Dr.Jit arrays to be written in place share memory: variables {indices}")


def overwrite(arrays: Iterable[Any], values: Iterable[Any]) -> None:
    """Write each of `values` (a number, or a flat array of the array's width) into the memory of the
    evaluated Dr.Jit array beside it, in place: the arrays, and so a frozen recording's inputs, stay what
    they were. The caller has waited for the kernels that read them (drjit.sync_thread)."""
    for array, value in zip(arrays, values, strict=True):
        np.asarray(array)[...] = value
