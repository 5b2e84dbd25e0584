"""GDR-Net training losses (paper eq. 7-8): coord, mask, region, point matching, centroid, z.

Each term is a pure function of predictions and targets; `pose_losses` weights and sums them. The point
matching term of a symmetric object is the minimum over the symmetric poses of the GT (GDR-Net's
PM_LOSS_SYM).
"""

from __future__ import annotations

from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import Tensor

from posenet.config import LossConfig
from posenet.geometry import decode_pose, symmetric_poses
from posenet.training.amp import full_precision

LOSS_TERMS = ("coord", "mask", "region", "pm", "cent", "z")  # paper eq. 7


def coord_loss(xyz: Tensor, target: Tensor, visible: Tensor) -> Tensor:
    """Masked L1 on normalised xyz: sum over channels and visible pixels / number of visible pixels."""
    return ((xyz - target).abs() * visible).sum() / visible.sum().clamp(min=1.0)


def mask_loss(mask: Tensor, target: Tensor, kind: str) -> Tensor:
    """Visible-mask loss on the head's mask channel: BCE taking it as logits ('bce', GDR-Net's `BCE`
    option) or, as GDR-Net's default `L1`, the mean L1 of the raw channel against the 0/1 mask ('l1')."""
    if kind == "bce":
        return F.binary_cross_entropy_with_logits(mask, target)
    return (mask - target).abs().mean()


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


class PmObject(NamedTuple):
    """The object as the point-matching loss sees it (posenet.training.train.pm_loss_points builds it)."""

    points: Tensor  # (N, 3) model points scaled by 1 / max(extent), so that the loss is unit-free
    symmetries: Tensor  # (K, 4, 4) the object's symmetry transforms, identity first; their rotations enter


def closest_symmetric_rotation(
    R_pred: Tensor, R_gt: Tensor, t_gt: Tensor, obj: PmObject, max_block: int = 2**22
) -> Tensor:
    """Per sample, the rotation of the GT's symmetric pose with the smallest PM loss against R_pred.

    pm_loss against it is the minimum over the symmetric poses of the GT (GDR-Net picks the pose of the
    smallest angle instead; both pick the pose R_pred equals, if any). The choice carries no gradient, and
    the candidates are scored at most `max_block` coordinates at a time.
    """
    if len(obj.symmetries) == 1:
        return R_gt  # no symmetry, no choice: the plain loss, step for step
    with torch.no_grad():
        candidates, _ = symmetric_poses(R_gt, t_gt, obj.symmetries)  # (B, K, 3, 3)
        diff = R_pred.detach()[:, None] - candidates
        chunk = max(1, max_block // (len(diff) * obj.points.numel()))
        blocks = diff.split(chunk, dim=1)  # one matrix product each: (B * k * 3, 3) @ (3, N)
        err = torch.cat(
            [(d.reshape(-1, 3) @ obj.points.T).abs().reshape(*d.shape[:2], -1).mean(-1) for d in blocks], 1
        )
        return candidates[torch.arange(len(diff), device=diff.device), err.argmin(1)]


def pose_losses(
    out: dict[str, Tensor], batch: dict[str, Tensor], pm: PmObject, cfg: LossConfig
) -> tuple[Tensor, dict[str, Tensor]]:
    """(weighted total, {term: unweighted value}) for one batch of network outputs and dataset targets.

    Under autocast (mixed precision), pose decoding and the point-matching loss still run in float32, and
    the SITE terms take the float32 SITE.
    """
    visible = batch["roi_mask_visib"]
    site = out["site"].float()
    with full_precision(visible.device):
        R_pred, _ = decode_pose({"rot6d": out["rot6d"].float(), "site": site}, batch)
        R_target = closest_symmetric_rotation(R_pred, batch["R"], batch["t"], pm)
        pm_term = pm_loss(R_pred, R_target, pm.points)
    terms = {
        "coord": coord_loss(out["xyz"], batch["roi_xyz"], visible),
        "mask": mask_loss(out["mask"], visible, cfg.mask_type),
        "region": region_loss(out["region"], batch["roi_region"], visible),
        "pm": pm_term,
        "cent": F.l1_loss(site[:, :2], batch["site"][:, :2]),
        "z": F.l1_loss(site[:, 2], batch["site"][:, 2]),
    }
    total = sum(getattr(cfg, name) * value for name, value in terms.items())
    return total, terms
