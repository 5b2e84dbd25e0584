"""Patch-PnP (GDR-Net's ConvPnPNet) with the optional PGSA token attention of the paper (§3.4)."""

from __future__ import annotations

import torch
from torch import Tensor, nn

from posenet.models.layers import conv_norm_relu


class PGSA(nn.Module):
    """Self-attention over the 8×8 patch tokens: Z̃ = Z + γ·proj(MHSA(LN(Z + P))), γ = 0 at init.

    Attention is written out (64 tokens) rather than via SDPA so FLOP counters see it on every device.
    """

    def __init__(self, channels: int, num_tokens: int, heads: int) -> None:
        super().__init__()
        self.heads = heads
        self.pos = nn.Parameter(torch.zeros(1, num_tokens, channels))
        nn.init.trunc_normal_(self.pos, std=0.02)
        self.norm = nn.LayerNorm(channels)
        self.qkv = nn.Linear(channels, 3 * channels)
        self.proj = nn.Linear(channels, channels)
        self.gamma = nn.Parameter(torch.zeros(1))

    def forward(self, z: Tensor) -> Tensor:
        b, c, h, w = z.shape
        tokens = z.flatten(2).transpose(1, 2)  # (B, N, C)
        qkv = self.qkv(self.norm(tokens + self.pos)).reshape(b, h * w, 3, self.heads, c // self.heads)
        q, k, v = qkv.permute(2, 0, 3, 1, 4)  # each (B, heads, N, d)
        weights = (q @ k.transpose(-2, -1) * q.shape[-1] ** -0.5).softmax(-1)
        attended = (weights @ v).transpose(1, 2).reshape(b, h * w, c)
        tokens = tokens + self.gamma * self.proj(attended)
        return tokens.transpose(1, 2).reshape(b, c, h, w)


class PatchPnP(nn.Module):
    """Three stride-2 conv-GN-ReLU blocks, [PGSA], flatten, FC stack with LeakyReLU, then rot6d and SITE.

    GroupNorm, as GDR-Net's ConvPnPNet. PyTorch's default init, as the geometric head (see GeoHead).
    """

    def __init__(
        self,
        in_channels: int,
        channels: int,
        in_res: int,
        fc_dims: tuple[int, ...],
        pgsa_heads: int | None,
    ) -> None:
        super().__init__()
        self.encoder = nn.Sequential(
            conv_norm_relu(in_channels, channels, stride=2),
            conv_norm_relu(channels, channels, stride=2),
            conv_norm_relu(channels, channels, stride=2),
        )
        num_tokens = (in_res // 8) ** 2
        self.pgsa = PGSA(channels, num_tokens, pgsa_heads) if pgsa_heads else nn.Identity()
        dims = (channels * num_tokens, *fc_dims)
        fc: list[nn.Module] = [nn.Flatten()]
        for d_in, d_out in zip(dims[:-1], dims[1:], strict=True):
            fc += [nn.Linear(d_in, d_out), nn.LeakyReLU(0.1, inplace=True)]
        self.fc = nn.Sequential(*fc)
        self.fc_r = nn.Linear(dims[-1], 6)
        self.fc_t = nn.Linear(dims[-1], 3)

    def forward(self, x: Tensor) -> tuple[Tensor, Tensor]:
        """Return (rot6d B×6, SITE B×3)."""
        h = self.fc(self.pgsa(self.encoder(x)))
        return self.fc_r(h), self.fc_t(h)
