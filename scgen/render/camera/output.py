"""The file's pixels: the output curve and quantisation to 8 or 16 bits, RGB or one channel."""

from __future__ import annotations

import functools

import numpy as np


def encode(value: np.ndarray, curve: str, bits: int) -> np.ndarray:
    """Linear values (H x W x C, clipped to [0, 1]) -> uint8 / uint16 codes through the sRGB curve or
    linearly; a one-channel image comes out H x W."""
    return _one_channel(_encode(value, curve, bits))


def _encode(value: np.ndarray, curve: str, bits: int) -> np.ndarray:
    x = np.clip(value, 0.0, 1.0)
    if curve == "srgb":
        x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(x * (2**bits - 1)).astype(np.uint8 if bits == 8 else np.uint16)


def _one_channel(codes: np.ndarray) -> np.ndarray:
    return codes[..., 0] if codes.shape[-1] == 1 else codes


@functools.lru_cache(maxsize=8)
def code_table(adc_bits: int, curve: str, bits: int) -> np.ndarray:
    """encode's output for each of the sensor's ADC codes, as the sensor hands them on
    (scgen.render.camera.sensor.expose: code / top in float32), read-only."""
    top = 2**adc_bits - 1
    table = _encode((np.arange(top + 1, dtype=np.float32) / np.float32(top)).astype(np.float32), curve, bits)
    table.flags.writeable = False
    return table


@functools.lru_cache(maxsize=8)
def saturated_code(adc_bits: int) -> int:
    """The least ADC code that expose hands on as 1.0 or more (a saturated pixel)."""
    top = 2**adc_bits - 1
    return int(np.argmax((np.arange(top + 1, dtype=np.float32) / np.float32(top)).astype(np.float32) >= 1.0))


def encode_codes(codes: np.ndarray, adc_bits: int, curve: str, bits: int) -> np.ndarray:
    """encode(expose(...)) from expose_codes' ADC codes (float32 whole numbers), by table: the same
    pixels, without the curve's power function on every one."""
    return _one_channel(code_table(adc_bits, curve, bits)[codes.astype(np.intp)])


def linear_to_srgb8(x: np.ndarray) -> np.ndarray:
    """Linear radiance -> 8-bit sRGB, clipped (the ideal camera's file)."""
    return encode(x, "srgb", 8)
