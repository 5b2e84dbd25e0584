"""Small building blocks shared by the geometric head and Patch-PnP."""

from __future__ import annotations

import math

from torch import nn


def norm2d(kind: str, channels: int) -> nn.Module:
    """'gn': GroupNorm with 32 groups, or fewer when the width is not a multiple of 32 (GDR-Net's Patch-PnP
    norm, and GDRNPP's head norm); 'bn': BatchNorm (GDR-Net's head norm, `ROT_HEAD.NORM="BN"`)."""
    if kind == "bn":
        return nn.BatchNorm2d(channels)
    return nn.GroupNorm(math.gcd(32, channels), channels)


def conv_norm_relu(in_channels: int, out_channels: int, stride: int = 1, norm: str = "gn") -> nn.Sequential:
    """3×3 conv (no bias, a norm follows) + norm (`norm2d`) + ReLU: GDR-Net's basic head block."""
    return nn.Sequential(
        nn.Conv2d(in_channels, out_channels, 3, stride, 1, bias=False),
        norm2d(norm, out_channels),
        nn.ReLU(inplace=True),
    )


def conv1x1(in_channels: int, out_channels: int) -> nn.Conv2d:
    """Pointwise conv with bias."""
    return nn.Conv2d(in_channels, out_channels, 1)
