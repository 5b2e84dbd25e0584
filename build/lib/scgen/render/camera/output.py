"""The file's pixels: the output curve and quantisation to 8 or 16 bits, RGB or one channel."""

from __future__ import annotations

import numpy as np


def encode(value: np.ndarray, curve: str, bits: int) -> np.ndarray:
    """Linear values (H x W x C, clipped to [0, 1]) -> uint8 / uint16 codes through the sRGB curve or
    linearly; a one-channel image comes out H x W."""
    x = np.clip(value, 0.0, 1.0)
    if curve == "srgb":
        x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    codes = np.round(x * (2**bits - 1)).astype(np.uint8 if bits == 8 else np.uint16)
    return codes[..., 0] if codes.shape[-1] == 1 else codes


def linear_to_srgb8(x: np.ndarray) -> np.ndarray:
    """Linear radiance -> 8-bit sRGB, clipped (the ideal camera's file)."""
    return encode(x, "srgb", 8)
