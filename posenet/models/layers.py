"""Small building blocks shared by the geometric head and Patch-PnP."""

from __future__ import annotations

import math

from torch import nn


def group_norm(channels: int) -> nn.GroupNorm:
    """GroupNorm with GDR-Net's 32 groups, or fewer when the width is not a multiple of 32."""
    return nn.GroupNorm(math.gcd(32, channels), channels)


def conv_gn_relu(in_channels: int, out_channels: int, stride: int = 1) -> nn.Sequential:
    """3×3 conv (no bias, GN follows) + GN + ReLU: GDR-Net's basic head block."""
    return nn.Sequential(
        nn.Conv2d(in_channels, out_channels, 3, stride, 1, bias=False),
        group_norm(out_channels),
        nn.ReLU(inplace=True),
    )


def conv1x1(in_channels: int, out_channels: int) -> nn.Conv2d:
    """Pointwise conv with bias."""
    return nn.Conv2d(in_channels, out_channels, 1)
