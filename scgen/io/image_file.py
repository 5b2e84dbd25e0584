"""Decoding the dataset's image files (RGB, masks, depth), and saying in words why one cannot be read.

libpng writes its own "libpng error: ..." line to the process's stderr when OpenCV decodes a damaged PNG,
whatever OpenCV's log level; the callers here report the file and the cause in one line of their own,
so that line is kept off the terminal.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path

import cv2
import numpy as np

from scgen.errors import ScgenError


def read_image(path: Path, flags: int = cv2.IMREAD_UNCHANGED) -> np.ndarray | None:
    """OpenCV's decode of the file at `path` with `flags`, or None when it is missing or not decodable."""
    try:
        data = np.fromfile(path, np.uint8)
    except OSError:
        return None
    if data.size == 0:
        return None
    with _quiet_stderr():
        return cv2.imdecode(data, flags)


def why_unreadable(path: Path) -> str:
    """The cause, in words, of a file read_image returned None for."""
    if not path.exists():
        return "no such file"
    if not path.is_file():
        return "not a file"
    return "empty file" if path.stat().st_size == 0 else "truncated or not an image"


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """File descriptor 2 pointed at /dev/null for the block (a C library's prints included)."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def check_images(paths: Iterable[Path], what: str = "image") -> None:
    """Decode every file before any work starts (a user's backgrounds): the first that cannot be read is
    one ScgenError line naming it and why."""
    for path in paths:
        if read_image(Path(path), cv2.IMREAD_COLOR) is None:
            raise ScgenError(f"cannot read {what} {path}: {why_unreadable(Path(path))}")
