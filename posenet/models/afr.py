"""AFR (paper §3.3): GGCA ‖ MECS on the decoded 64×64 feature, fused, added back with γ_afr = 0 at init.

MECS follows the paper's equations literally (eqs. mecs_channel to mecs_output): a GELU 1×1 input
projection, then channel and spatial attention with no gate on the channel descriptors' MLP outputs and no
output projection, so it holds two C×C 1×1 convs (reference `gdrnet.md` §6.3, reading A: AFR 0.391M at
C=256; the paper's +0.45M matched reading D, which adds a third C×C 1×1 as an output projection). The
fusion is 1×1 (n·C → C), GELU, 1×1 (C → C), with n the number of enabled branches.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from posenet.models.layers import conv1x1


class GGCA(nn.Module):
    """Grouped coordinate attention: per channel group, one sigmoid gate per row and one per column.

    Each group's avg‖max descriptors along W (per row) and along H (per column) go through a projection
    φ shared by both axes and all groups (1×1 conv, BN, ReLU; reduction r of the group width), then
    f_h / f_w expand back to the group width. Output = group feature ⊙ A_h ⊙ A_w.
    """

    def __init__(self, channels: int, groups: int, reduction: int) -> None:
        super().__init__()
        self.groups = groups
        width = channels // groups
        mid = width // reduction
        self.shared = nn.Sequential(conv1x1(2 * width, mid), nn.BatchNorm2d(mid), nn.ReLU(inplace=True))
        self.f_h = conv1x1(mid, width)
        self.f_w = conv1x1(mid, width)

    def forward(self, x: Tensor) -> Tensor:
        b, c, h, w = x.shape
        g = x.reshape(b * self.groups, c // self.groups, h, w)
        d_h = torch.cat([g.mean(3, keepdim=True), g.amax(3, keepdim=True)], 1)  # (bG, 2c/G, h, 1)
        d_w = torch.cat([g.mean(2, keepdim=True), g.amax(2, keepdim=True)], 1).transpose(2, 3)  # (.., w, 1)
        y_h, y_w = self.shared(torch.cat([d_h, d_w], 2)).split([h, w], 2)
        a_h = torch.sigmoid(self.f_h(y_h))
        a_w = torch.sigmoid(self.f_w(y_w)).transpose(2, 3)
        return (g * a_h * a_w).reshape(b, c, h, w)


def channel_descriptors(x: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Spatial average, max and median of each channel (B×C each); the median ignores lone outliers."""
    flat = x.flatten(2)
    return flat.mean(2), flat.amax(2), flat.median(2).values


class MedianChannelAttention(nn.Module):
    """A_c = Σ_ρ ψ(ρ(X)) over ρ ∈ {avg, max, median} with one shared MLP ψ (reduction r), eq. mecs_channel.

    As written in the paper, no sigmoid gates the sum or its terms: A_c is an unbounded channel scale.
    """

    def __init__(self, channels: int, reduction: int) -> None:
        super().__init__()
        hidden = channels // reduction
        self.mlp = nn.Sequential(
            nn.Linear(channels, hidden), nn.ReLU(inplace=True), nn.Linear(hidden, channels)
        )

    def forward(self, x: Tensor) -> Tensor:
        return self.mlp(torch.stack(channel_descriptors(x))).sum(0)[:, :, None, None]  # (3, B, C) summed


def strip_conv(channels: int, k: int) -> nn.Sequential:
    """Depth-wise 1×k then k×1: a k×k directional receptive field at 2k weights per channel."""
    return nn.Sequential(
        nn.Conv2d(channels, channels, (1, k), padding=(0, k // 2), groups=channels),
        nn.Conv2d(channels, channels, (k, 1), padding=(k // 2, 0), groups=channels),
    )


class MECS(nn.Module):
    """Median-enhanced channel then multi-scale strip spatial attention on a GELU 1×1 projection.

    X = GELU(W_in x); X_c = A_c ⊙ X; B = DW5×5(X_c); S = Σ_k DW k×1(DW 1×k(B)); F_mecs = σ(W_s S) ⊙ X_c.
    """

    def __init__(self, channels: int, reduction: int, kernels: tuple[int, ...]) -> None:
        super().__init__()
        self.proj_in = nn.Sequential(conv1x1(channels, channels), nn.GELU())
        self.channel_attention = MedianChannelAttention(channels, reduction)
        self.base = nn.Conv2d(channels, channels, 5, padding=2, groups=channels)
        self.strips = nn.ModuleList(strip_conv(channels, k) for k in kernels)
        self.spatial = conv1x1(channels, channels)

    def forward(self, x: Tensor) -> Tensor:
        x = self.proj_in(x)
        x_c = self.channel_attention(x) * x
        base = self.base(x_c)
        s = sum(strip(base) for strip in self.strips)
        return torch.sigmoid(self.spatial(s)) * x_c


class AFR(nn.Module):
    """F_afr = F + γ·fuse([GGCA(F) ‖ MECS(F)]); with one branch enabled the fusion input is C wide."""

    def __init__(
        self, channels: int, ggca: bool, mecs: bool, groups: int, reduction: int, kernels: tuple[int, ...]
    ) -> None:
        super().__init__()
        if not (ggca or mecs):
            raise ValueError("AFR needs at least one of GGCA, MECS")
        self.branches = nn.ModuleDict()
        if ggca:
            self.branches["ggca"] = GGCA(channels, groups, reduction)
        if mecs:
            self.branches["mecs"] = MECS(channels, reduction, kernels)
        self.fuse = nn.Sequential(
            conv1x1(len(self.branches) * channels, channels), nn.GELU(), conv1x1(channels, channels)
        )
        self.gamma = nn.Parameter(torch.zeros(1))

    def forward(self, x: Tensor) -> Tensor:
        fused = self.fuse(torch.cat([branch(x) for branch in self.branches.values()], 1))
        return x + self.gamma * fused
