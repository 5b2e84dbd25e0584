"""Atomic file writes: write a temporary sibling, then rename, so readers never see half a file."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

TMP_MARK = ".tmp-"


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write `data` to a temporary sibling, then rename it to `path`; a failed write (a full disk)
    removes the temporary and raises."""
    tmp = path.with_name(f"{path.name}{TMP_MARK}{os.getpid()}")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except OSError:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, text.encode())


def remove_stale_temporaries(root: Path) -> int:
    """Delete temporaries left by a killed run; returns how many were removed."""
    n = 0
    for p in root.rglob(f"*{TMP_MARK}*"):
        p.unlink(missing_ok=True)
        n += 1
    return n
