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
