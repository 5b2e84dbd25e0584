"""What scgen keeps on this machine between runs: derived data too slow to make in every process.

One folder, SCGEN_CACHE_DIR, else XDG_CACHE_HOME/scgen or ~/.cache/scgen. Each entry is kept under a
digest of everything it was made from, so a changed input is a new entry and never a stale one; where
the folder cannot be read or written (a read-only home), the data is made again, as without a cache.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import zipfile
from collections.abc import Callable, Sequence
from pathlib import Path

import cv2
import numpy as np

from scgen.io.atomic import atomic_write_bytes

CACHE_ENV = "SCGEN_CACHE_DIR"
ARRAYS_KEPT = 2  # entries kept per name: an upgrade's new one beside the last, then the oldest goes


def cache_dir() -> Path:
    """SCGEN_CACHE_DIR, else XDG_CACHE_HOME/scgen or ~/.cache/scgen (RuntimeError: no home to find)."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "scgen"


def inputs_digest(code: Sequence[Path], data: Sequence[Path]) -> str:
    """A digest of what arrays are made from: the code that makes them (its bytes), the files it reads
    (size and modification time), and the numpy and OpenCV they are made with."""
    digest = hashlib.sha256()
    for path in code:
        digest.update(Path(path).read_bytes())
    stats = [(str(p), (st := p.stat()).st_size, st.st_mtime_ns) for p in map(Path, data)]
    digest.update(json.dumps([stats, np.__version__, cv2.__version__]).encode())
    return digest.hexdigest()[:20]


def cached_arrays(
    name: str, code: Sequence[Path], data: Sequence[Path], make: Callable[[], tuple[np.ndarray, ...]]
) -> tuple[np.ndarray, ...]:
    """make()'s arrays, read from the cache when an entry of these inputs (inputs_digest) is there, else
    made and kept (the older entries of `name` beyond ARRAYS_KEPT removed)."""
    path = _entry(name, code, data)
    if path is not None:
        unreadable = (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile)  # none yet, or damaged
        with contextlib.suppress(*unreadable), np.load(path) as kept:
            return tuple(kept[f"arr_{i}"] for i in range(len(kept.files)))
    arrays = make()
    if path is not None:
        with contextlib.suppress(OSError):  # a full disk, a read-only home: nothing kept
            _keep(path, name, arrays)
    return arrays


def _entry(name: str, code: Sequence[Path], data: Sequence[Path]) -> Path | None:
    """The cache file of these inputs, or None where there is no cache folder to name (no home) or the
    inputs cannot be read."""
    try:
        return cache_dir() / f"{name}-{inputs_digest(code, data)}.npz"
    except (RuntimeError, OSError):  # no home; code or data that cannot be read as files (a zipped package)
        return None


def _keep(path: Path, name: str, arrays: tuple[np.ndarray, ...]) -> None:
    """Write the entry whole or not at all, then drop the oldest entries of `name` beyond ARRAYS_KEPT."""
    path.parent.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    np.savez(buffer, *arrays)  # stored, not compressed: read back at disk speed
    atomic_write_bytes(path, buffer.getvalue())
    others = sorted(
        (p for p in path.parent.glob(f"{name}-*.npz") if p != path), key=lambda p: p.stat().st_mtime_ns
    )
    for stale in others[: max(len(others) - (ARRAYS_KEPT - 1), 0)]:  # the newest others stay beside `path`
        stale.unlink(missing_ok=True)
