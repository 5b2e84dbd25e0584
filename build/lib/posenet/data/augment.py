"""The paper's training augmentations on a cropped RoI: brightness/contrast and background replacement;
and GDR-Net's foreground truncation (TRUNCATE_FG) with it.

(Scale perturbation is DZI jitter, see crop.py; the albumentations chains are in photometric.py.)
Backgrounds come from the dataset's own images with the target painted out, or are procedural noise:
nothing is downloaded.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np


def brightness_contrast(
    img: np.ndarray, rng: np.random.Generator, brightness: tuple[float, float], contrast: tuple[float, float]
) -> np.ndarray:
    """float32 RGB in [0, 1]: contrast about the mean grey level, then a brightness gain; clipped."""
    c, b = rng.uniform(*contrast), rng.uniform(*brightness)
    mean = img.mean()
    return np.clip(((img - mean) * c + mean) * b, 0.0, 1.0)


def noise_background(res: int, rng: np.random.Generator) -> np.ndarray:
    """A res x res float32 RGB background: smooth colour noise, fine grain and a sprinkle of stars."""
    cells = int(rng.integers(2, 17))
    coarse = rng.uniform(0.0, rng.uniform(0.1, 1.0), size=(cells, cells, 3)).astype(np.float32)
    img = cv2.resize(coarse, (res, res), interpolation=cv2.INTER_CUBIC)
    img += rng.standard_normal(img.shape, dtype=np.float32) * np.float32(rng.uniform(0.0, 0.05))
    stars = rng.integers(0, res, size=(int(rng.integers(0, res // 4 + 1)), 2))
    img[stars[:, 1], stars[:, 0]] = rng.uniform(0.5, 1.0, size=(len(stars), 1))
    return np.clip(img, 0.0, 1.0)


def paint_out(rgb: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """uint8 RGB with the (dilated) mask region inpainted from its surroundings: a target-free background."""
    grown = cv2.dilate(mask.astype(np.uint8), np.ones((5, 5), np.uint8))
    return cv2.inpaint(rgb, grown, 3, cv2.INPAINT_TELEA)


def random_view(bg: np.ndarray, res: int, rng: np.random.Generator) -> np.ndarray:
    """A random square window of `bg` (uint8 RGB), flipped at random, resized to res x res float32 [0, 1]."""
    h, w = bg.shape[:2]
    side = int(rng.integers(min(h, w) // 3, min(h, w) + 1))
    y, x = int(rng.integers(0, h - side + 1)), int(rng.integers(0, w - side + 1))
    win = bg[y : y + side, x : x + side]
    if rng.random() < 0.5:
        win = win[:, ::-1]
    return (
        cv2.resize(np.ascontiguousarray(win), (res, res), interpolation=cv2.INTER_LINEAR).astype(np.float32)
        / 255
    )


def replace_background(img: np.ndarray, keep: np.ndarray, bg: np.ndarray) -> np.ndarray:
    """Pixels where `keep` is 0 replaced by `bg` (all float32 RGB, same size)."""
    return np.where(keep[..., None] > 0, img, bg)


class Cut(NamedTuple):
    """A straight cut across a RoI, in coordinates normalised to the RoI side (0 to 1): pixels whose centre
    lies on the dropped side of `line` along `axis` (0: rows, 1: columns) are cut away."""

    axis: int
    line: float
    drop_before: bool  # True: drop what lies before the line (top / left), else after it


def draw_cut(visible: np.ndarray, rng: np.random.Generator) -> Cut | None:
    """GDR-Net's TRUNCATE_FG (`trunc_mask`): with probability 0.2 each, cut the visible target's top,
    bottom, left or right part at a line drawn uniformly between its box edge and its box centre; else
    (0.2, or nothing visible) no cut."""
    rows, cols = np.nonzero(visible)
    side = rng.random()
    if side >= 0.8 or not len(rows):
        return None
    res = visible.shape[0]
    axis = 0 if side < 0.4 else 1
    coords = (rows if axis == 0 else cols) + 0.5
    lo, hi = coords.min() / res, coords.max() / res
    centre = (lo + hi) / 2
    before = side < 0.2 or 0.4 <= side < 0.6
    return Cut(axis, rng.uniform(lo, centre) if before else rng.uniform(centre, hi), before)


def apply_cut(mask: np.ndarray, cut: Cut | None) -> np.ndarray:
    """`mask` (res x res, any resolution of the same RoI) with the cut-away pixels zeroed."""
    if cut is None:
        return mask
    centres = (np.arange(mask.shape[0]) + 0.5) / mask.shape[0]
    dropped = centres < cut.line if cut.drop_before else centres >= cut.line
    out = mask.copy()
    if cut.axis == 0:
        out[dropped] = 0
    else:
        out[:, dropped] = 0
    return out
