"""One pose network class; every ablation row of the paper is a `ModelConfig` of it."""

from __future__ import annotations

from typing import Any

import torch
from torch import Tensor, nn

from posenet.models.afr import AFR
from posenet.models.backbone import Backbone
from posenet.models.config import ModelConfig
from posenet.models.geo_head import GeoHead
from posenet.models.pnp import PatchPnP


def pnp_in_channels(num_regions: int) -> int:
    """Channels of `pnp_input`: xyz 3, visible mask 1, surface regions, RoI coordinates 2."""
    return 3 + 1 + num_regions + 2


def pnp_input(xyz: Tensor, mask: Tensor, region: Tensor, roi_coord2d: Tensor) -> Tensor:
    """X_pnp = concat[M_2D-3D, M_vis, M_SRA, U_roi] from the head's raw outputs (mask and region logits).

    M_vis is the mask probability (sigmoid), M_SRA the softmax over the regions without background.
    """
    return torch.cat([xyz, mask.sigmoid(), region[:, 1:].softmax(1), roi_coord2d], 1)


class PoseNet(nn.Module):
    """Backbone → geometric head [AFR] → (mask, xyz, region) → Patch-PnP [PGSA] → (rot6d, SITE).

    Patch-PnP sees the paper's X_pnp = Φ(concat[M_2D-3D, M_vis, M_SRA], U_roi) (eq. pnp_input_overall):
    concat[xyz, sigmoid(mask), softmax(region[1:]), roi_coord2d], 3 + 1 + num_regions + 2 channels. (GDR-Net
    leaves the mask out; the paper lists the visible mask among the inputs.) Pose decoding lives in
    `posenet.geometry`.
    """

    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        self.config = config
        self.backbone = Backbone(config.backbone, config.pretrained)
        afr = None
        if config.ggca or config.mecs:
            afr = AFR(
                config.head_channels,
                ggca=config.ggca,
                mecs=config.mecs,
                groups=config.afr_groups,
                reduction=config.afr_reduction,
                kernels=config.mecs_kernels,
            )
        self.geo_head = GeoHead(
            self.backbone.out_channels, config.head_channels, config.num_regions, afr, config.head_norm
        )
        self.pnp = PatchPnP(
            in_channels=pnp_in_channels(config.num_regions),
            channels=config.pnp_channels,
            in_res=config.output_res,
            fc_dims=config.fc_dims,
            pgsa_heads=config.pgsa_heads if config.pgsa else None,
        )

    def forward(self, roi_img: Tensor, roi_coord2d: Tensor) -> dict[str, Tensor]:
        """roi_img B×3×R×R in [0, 1], roi_coord2d B×2×r×r → dict of head outputs (see module docs)."""
        features, mask, xyz, region = self.geo_head(self.backbone(roi_img))
        rot6d, site = self.pnp(pnp_input(xyz, mask, region, roi_coord2d))
        return {
            "mask": mask,
            "xyz": xyz,
            "region": region,
            "rot6d": rot6d,
            "site": site,
            "features": features,
        }

    def config_dict(self) -> dict[str, Any]:
        """JSON-able identity of the architecture, stored in checkpoints; `create_model(**d)` rebuilds it."""
        return self.config.to_dict()


def create_model(variant: str, preset: str = "paper", **overrides: Any) -> PoseNet:
    """Paper variant `variant` in the `preset` configuration (paper or smoke), any field overridden.

    The one way to build a network, as timm's `create_model`: training, evaluation, bench and tests use
    it, and `create_model(**checkpoint["model_config"])` rebuilds a saved one. `ModelConfig.create`
    validates the arguments.
    """
    return PoseNet(ModelConfig.create(variant, preset, **overrides))
