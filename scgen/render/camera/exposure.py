"""Per-image exposure: the drawn EV shift, or auto-exposure on the target's visible pixels; then, in both,
highlight protection on the whole frame.

Highlight protection is what a camera's auto-exposure adds to metering its subject: when more than
`max_clipped` of the frame's pixels would clip (any channel at or above 1), the exposure is shortened
(EV raised) just enough that no more do, by at most the upper end of `auto_limits_ev`. It acts on the
linear image the scene gives the lens (before the sun's disc, flare and bloom, which no exposure
setting keeps from clipping). A `fixed` exposure is left as it is.
"""

from __future__ import annotations

import numpy as np

from scgen.render.conventions import LUMA
from scgen.scenes.config.camera import ExposureSettings

LUMA_32 = LUMA.astype(np.float32)  # float32 images stay float32
CLIP_MARGIN_EV = 1e-5  # keeps the (k+1)-th brightest pixel below 1 after float32 rounding


def luminance(image: np.ndarray) -> np.ndarray:
    """H x W linear luminance of an H x W x 3 (or x 1) linear image."""
    return image[..., 0] if image.shape[-1] == 1 else image @ LUMA_32


def exposure_shift_ev(
    exposure: ExposureSettings, drawn_ev: float, image: np.ndarray, visible: np.ndarray
) -> float:
    """EV added to the base exposure (the image at base exposure is `image`): the drawn shift, or (auto)
    the one that brings the mean luminance of the target's visible pixels to `auto_target`, within
    `auto_limits_ev` (0 when the target is unseen); then raised by highlight protection (not `fixed`)."""
    if exposure.mode == "fixed":
        return drawn_ev
    shift = drawn_ev if exposure.mode == "range" else metered_ev(exposure, image, visible)
    return max(shift, min(highlight_ev(image, exposure.max_clipped), exposure.auto_limits_ev[1]))


def metered_ev(exposure: ExposureSettings, image: np.ndarray, visible: np.ndarray) -> float:
    """Auto-exposure on the target: the EV that brings its visible pixels' mean luminance to
    `auto_target`, within `auto_limits_ev` (0 when the target is unseen)."""
    if not visible.any():
        return 0.0
    lo, hi = exposure.auto_limits_ev
    mean = float(luminance(image)[visible].mean())
    return float(np.clip(np.log2(mean / exposure.auto_target), lo, hi)) if mean > 0 else float(lo)


def highlight_ev(image: np.ndarray, max_clipped: float) -> float:
    """The least EV at which at most `max_clipped` of the pixels clip: a pixel clips at EV s when its
    brightest channel is >= 2^s, so s is just above log2 of the (k+1)-th brightest pixel,
    k = max_clipped * pixels (-inf when nothing is that bright)."""
    if image.ndim == 3:  # each pixel's brightest channel (np.maximum: a reduce over a short axis is slow)
        peak = image[..., 0].copy()
        for c in range(1, image.shape[-1]):
            np.maximum(peak, image[..., c], out=peak)
        peak = peak.ravel()
    else:
        peak = image.ravel()
    k = int(max_clipped * peak.size)
    if k >= peak.size:
        return -np.inf
    value = float(np.partition(peak, peak.size - 1 - k)[peak.size - 1 - k])
    return float(np.log2(value) + CLIP_MARGIN_EV) if value > 0 else -np.inf
