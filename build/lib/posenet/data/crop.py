"""Dynamic zoom-in (DZI): a square RoI around a box, and the affine that crops it to any resolution.

The input image (e.g. 256²) and the dense targets (e.g. 64²) are cropped from the full-resolution
images with the same square, so a pixel of either grid maps to the same image point. Pixel centres sit
at integer coordinates: the square [c - s/2, c + s/2] maps onto [-0.5, res - 0.5]. The RoI camera of a
crop is K_roi = [A; 0 0 1] @ K with A = crop_affine(roi, res).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class Roi:
    """A square crop: its centre and side (pixels), and the un-padded box size that SITE is relative to."""

    center: np.ndarray  # (2,)
    scale: float
    box_wh: np.ndarray  # (2,)


def box_center(bbox: tuple[float, float, float, float]) -> np.ndarray:
    """Centre of a box [x, y, w, h] that covers pixels x .. x + w - 1 (pixel-centre convention)."""
    x, y, w, h = bbox
    return np.array([x + (w - 1) / 2, y + (h - 1) / 2], dtype=np.float64)


def roi_from_box(
    bbox: tuple[float, float, float, float],
    image_size: tuple[int, int],
    pad_scale: float,
    jitter: tuple[float, float] | None = None,
    rng: np.random.Generator | None = None,
) -> Roi:
    """The DZI square for `bbox`: side max(w, h) * pad_scale, clamped to the image's larger side.

    With `jitter` = (scale_ratio, shift_ratio) and `rng`, the side is scaled by 1 + scale_ratio * U(-1, 1)
    and the centre shifted by shift_ratio * U(-1, 1) box sizes per axis (training's scale perturbation).
    """
    w, h = max(float(bbox[2]), 1.0), max(float(bbox[3]), 1.0)
    center = box_center(bbox)
    ratio = 1.0
    if jitter is not None and rng is not None:
        scale_ratio, shift_ratio = jitter
        ratio = 1.0 + scale_ratio * rng.uniform(-1.0, 1.0)
        center = center + shift_ratio * rng.uniform(-1.0, 1.0, size=2) * (w, h)
    scale = min(max(w, h) * pad_scale * ratio, float(max(image_size)))
    return Roi(center=center, scale=scale, box_wh=np.array([w, h], dtype=np.float64))


def box_in_roi(bbox: tuple[float, float, float, float], roi: Roi) -> tuple[float, float, float, float]:
    """The box [x, y, w, h] (pixel edges) as (x0, y0, x1, y1) in coordinates normalised to the RoI square
    (0 to 1), clipped to it."""
    x, y, w, h = (float(v) for v in bbox)
    # box_center's convention: pixel x covers [x - 0.5, x + 0.5], so the box spans [x - 0.5, x + w - 0.5]
    edges = np.array([x - 0.5, y - 0.5, x + w - 0.5, y + h - 0.5])
    norm = (edges - np.tile(roi.center, 2)) / roi.scale + 0.5
    x0, y0, x1, y1 = np.clip(norm, 0.0, 1.0)
    return float(x0), float(y0), float(x1), float(y1)


def crop_affine(roi: Roi, res: int, offset: tuple[int, int] = (0, 0)) -> np.ndarray:
    """2x3 affine from image pixels (of a sub-image starting at `offset` = (x0, y0)) to RoI pixels."""
    s = res / roi.scale
    c = (res - 1) / 2
    return np.array(
        [
            [s, 0.0, c + (offset[0] - roi.center[0]) * s],
            [0.0, s, c + (offset[1] - roi.center[1]) * s],
        ],
        dtype=np.float64,
    )


def crop(img: np.ndarray, roi: Roi, res: int, nearest: bool, offset: tuple[int, int] = (0, 0)) -> np.ndarray:
    """Crop `img` (or a sub-image of it starting at `offset`) to res x res; zero outside the image."""
    flags = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    return cv2.warpAffine(img, crop_affine(roi, res, offset), (res, res), flags=flags, borderValue=0)


def roi_pixel_centres(center: np.ndarray, scale: float, res: int) -> tuple[np.ndarray, np.ndarray]:
    """Image coordinates u (of each RoI column) and v (of each RoI row) of the res x res RoI pixel centres
    of the square of side `scale` around `center` (the inverse of crop_affine)."""
    grid = (np.arange(res, dtype=np.float64) - (res - 1) / 2) * (scale / res)
    return grid + center[0], grid + center[1]


def roi_coord2d(roi: Roi, res: int, image_size: tuple[int, int]) -> np.ndarray:
    """2 x res x res image coordinates (u / W, v / H) of each RoI pixel centre (GDR-Net's 'abs' coor2d)."""
    u, v = roi_pixel_centres(roi.center, roi.scale, res)
    u, v = u / image_size[0], v / image_size[1]
    return np.stack(np.broadcast_arrays(u[None, :], v[:, None])).astype(np.float32)
