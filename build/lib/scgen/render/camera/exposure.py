"""Per-image exposure: the drawn EV shift, or auto-exposure on the target's visible pixels."""

from __future__ import annotations

from typing import Any

import numpy as np

from scgen.render.conventions import LUMA

LUMA_32 = LUMA.astype(np.float32)  # float32 images stay float32


def luminance(image: np.ndarray) -> np.ndarray:
    """H x W linear luminance of an H x W x 3 (or x 1) linear image."""
    return image[..., 0] if image.shape[-1] == 1 else image @ LUMA_32


def exposure_shift_ev(
    exposure: dict[str, Any], drawn_ev: float, image: np.ndarray, visible: np.ndarray
) -> float:
    """EV added to the base exposure: the drawn shift, or (auto) the one that brings the mean luminance of
    the target's visible pixels to `auto_target`, within `auto_limits_ev` (0 when the target is unseen)."""
    if exposure["mode"] != "auto":
        return drawn_ev
    if not visible.any():
        return 0.0
    lo, hi = exposure["auto_limits_ev"]
    mean = float(luminance(image)[visible].mean())
    return float(np.clip(np.log2(mean / exposure["auto_target"]), lo, hi)) if mean > 0 else float(lo)
