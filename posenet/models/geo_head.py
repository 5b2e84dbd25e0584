"""GDR-Net's TopDown geometric head: stride-32 feature → ×8 upsampled feature → mask, xyz, region."""

from __future__ import annotations

from torch import Tensor, nn

from posenet.models.layers import conv_norm_relu, norm2d


def top_down_decoder(in_channels: int, channels: int, norm: str) -> nn.Sequential:
    """Deconv ×2 + 2 convs, then twice [bilinear ×2 + 2 convs]: 8×8 → 64×64 at the paper's sizes; each
    followed by `norm` (layers.norm2d: GroupNorm, or GDR-Net's BatchNorm) and ReLU."""
    layers: list[nn.Module] = [
        nn.ConvTranspose2d(in_channels, channels, 3, 2, 1, output_padding=1, bias=False),
        norm2d(norm, channels),
        nn.ReLU(inplace=True),
        conv_norm_relu(channels, channels, norm=norm),
        conv_norm_relu(channels, channels, norm=norm),
    ]
    for _ in range(2):
        layers += [nn.UpsamplingBilinear2d(scale_factor=2), conv_norm_relu(channels, channels, norm=norm)]
        layers += [conv_norm_relu(channels, channels, norm=norm)]
    return nn.Sequential(*layers)


class GeoHead(nn.Module):
    """Decoder, optional feature refinement (AFR), and one shared 1×1 output conv.

    Output channels are ordered mask (1), xyz (3), region (num_regions + 1, channel 0 = background).
    Layers keep PyTorch's default init, not GDR-Net's N(0, 0.001): from a random backbone the tiny init
    cut the gradient reaching the backbone ~5x and slowed every head (docs/posenet.md).
    """

    def __init__(
        self, in_channels: int, channels: int, num_regions: int, refine: nn.Module | None, norm: str = "gn"
    ) -> None:
        super().__init__()
        self.decoder = top_down_decoder(in_channels, channels, norm)
        self.refine = refine if refine is not None else nn.Identity()
        self.out = nn.Conv2d(channels, 1 + 3 + num_regions + 1, 1)

    def forward(self, x: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """Return (features before the output conv, mask logits, xyz, region logits)."""
        features = self.refine(self.decoder(x))
        out = self.out(features)
        return features, out[:, :1], out[:, 1:4], out[:, 4:]
