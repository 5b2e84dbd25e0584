"""GDR-Net training losses (paper eq. 7-8): coord, mask, region, point matching, centroid, z.

Each term is a pure function of predictions and targets; `pose_losses` weights and sums them.
"""

from __future__ import annotations

import torch.nn.functional as F
from torch import Tensor

from posenet.config import LossConfig
from posenet.geometry import decode_pose

LOSS_TERMS = ("coord", "mask", "region", "pm", "cent", "z")  # paper eq. 7


def coord_loss(xyz: Tensor, target: Tensor, visible: Tensor) -> Tensor:
    """Masked L1 on normalised xyz: sum over channels and visible pixels / number of visible pixels."""
    return ((xyz - target).abs() * visible).sum() / visible.sum().clamp(min=1.0)


def mask_loss(logits: Tensor, target: Tensor, kind: str) -> Tensor:
    """Visible-mask loss: BCE on logits ('bce') or mean L1 of the sigmoid probability ('l1')."""
    if kind == "bce":
        return F.binary_cross_entropy_with_logits(logits, target)
    return (logits.sigmoid() - target).abs().mean()


def region_loss(logits: Tensor, labels: Tensor, visible: Tensor) -> Tensor:
    """Cross-entropy of the surface-region classes over visible pixels / number of visible pixels."""
    ce = F.cross_entropy(logits, labels, reduction="none")
    vis = visible[:, 0]
    return (ce * vis).sum() / vis.sum().clamp(min=1.0)


def pm_loss(R_pred: Tensor, R_gt: Tensor, points: Tensor) -> Tensor:
    """Point matching (rotation only): per-point L1 over xyz between R_pred p and R_gt p, mean over points.

    `points` (N x 3) are model points scaled by 1 / max(extent), so the loss is unit-free.
    """
    diff = points @ R_pred.transpose(-1, -2) - points @ R_gt.transpose(-1, -2)
    return 3.0 * diff.abs().mean()


def pose_losses(
    out: dict[str, Tensor], batch: dict[str, Tensor], pm_points: Tensor, cfg: LossConfig
) -> tuple[Tensor, dict[str, Tensor]]:
    """(weighted total, {term: unweighted value}) for one batch of network outputs and dataset targets."""
    visible = batch["roi_mask_visib"]
    R_pred, _ = decode_pose(out, batch)
    terms = {
        "coord": coord_loss(out["xyz"], batch["roi_xyz"], visible),
        "mask": mask_loss(out["mask"], visible, cfg.mask_type),
        "region": region_loss(out["region"], batch["roi_region"], visible),
        "pm": pm_loss(R_pred, batch["R"], pm_points),
        "cent": F.l1_loss(out["site"][:, :2], batch["site"][:, :2]),
        "z": F.l1_loss(out["site"][:, 2], batch["site"][:, 2]),
    }
    total = sum(getattr(cfg, name) * value for name, value in terms.items())
    return total, terms
