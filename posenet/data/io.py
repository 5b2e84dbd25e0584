"""Pixel readers for one instance: RGB, masks and the xyz map (contract: docs/dataset.md)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from posenet.errors import PosenetError
from scgen.io import read_image, read_xyz_exr, why_unreadable


def unreadable(kind: str, path: Path) -> PosenetError:
    """The error for an image file OpenCV could not decode: missing, or there and not decodable."""
    return PosenetError(f"cannot read {kind} {path}: {why_unreadable(path)}")


PNG_START = b"\x89PNG\r\n\x1a\n"  # a PNG's signature
PNG_END = b"IEND\xaeB`\x82"  # its last chunk's type and CRC: the file's last 8 bytes
JPEG_START, JPEG_END = b"\xff\xd8", b"\xff\xd9"  # SOI and EOI
JPEG_TAIL = 64  # EOI may be followed by a writer's padding; it cannot occur inside the coded data (0xff is
# stuffed there), so an EOI in the last bytes is the file's end


def image_fault(path: Path) -> str | None:
    """Why the PNG or JPEG file at `path` is not whole, from its first and last bytes only (no decode: a
    file cut short, as a broken copy or a full disk leaves it, lacks its end marker); None when whole."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(PNG_START))
            size = f.seek(0, 2)
            f.seek(max(0, size - JPEG_TAIL))
            tail = f.read()
    except OSError as exc:
        return f"cannot open it ({exc.strerror})"
    if size == 0:
        return "empty file"
    if head.startswith(PNG_START):
        return None if tail.endswith(PNG_END) else "truncated PNG (no IEND chunk at its end)"
    if head.startswith(JPEG_START):
        return None if JPEG_END in tail else "truncated JPEG (no end-of-image marker)"
    return "neither a PNG nor a JPEG file"


def read_bgr(path: Path) -> np.ndarray:
    """H x W x 3 uint8 in OpenCV's BGR order (callers flip to RGB after cropping: less to convert)."""
    img = read_image(path, cv2.IMREAD_COLOR)
    if img is None:
        raise unreadable("image", path)
    return img


def read_mask(path: Path) -> np.ndarray:
    """H x W uint8 in {0, 1}."""
    m = read_image(path, cv2.IMREAD_GRAYSCALE)
    if m is None:
        raise unreadable("mask", path)
    return (m > 127).astype(np.uint8)


def read_xyz(path: Path) -> np.ndarray:
    """The stored xyz crop (h x w x 3 float32, metres); it covers the instance's `xyz_box` of the image."""
    if not path.is_file():
        raise PosenetError(f"missing xyz map {path} (the dataset must ship xyz maps, see docs/dataset.md)")
    try:
        return read_xyz_exr(path)
    except (KeyError, RuntimeError, OSError) as exc:
        raise PosenetError(f"cannot read xyz map {path} (needs channels X, Y, Z): {exc}") from exc
