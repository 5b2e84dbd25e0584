"""Pose metrics per sample (batched torch, float64) and their dataset summary.

Rotation / translation error, ADD and ADD-S (BOP's ADD / ADI), and the ESA (SPEC) score with the
SPEC2021 calibration-precision thresholds applied independently to each term, as in SPNv2.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

ESA_THETA_Q_DEG = 0.169  # rotation errors below this count as 0 (SPEC2021 / SPEED+ HIL)
ESA_THETA_T = 2.173e-3  # normalised translation errors below this (2.173 mm per metre) count as 0


def rotation_error_deg(R_pred: Tensor, R_gt: Tensor) -> Tensor:
    """arccos((tr(R_pred^T R_gt) - 1) / 2) in degrees."""
    cos = ((R_pred.transpose(-1, -2) @ R_gt).diagonal(dim1=-2, dim2=-1).sum(-1) - 1.0) / 2.0
    return torch.rad2deg(torch.arccos(cos.clamp(-1.0, 1.0)))


def translation_error(t_pred: Tensor, t_gt: Tensor) -> Tensor:
    """Euclidean distance between translations (metres)."""
    return (t_pred - t_gt).norm(dim=-1)


def _transform(R: Tensor, t: Tensor, points: Tensor) -> Tensor:
    return points @ R.transpose(-1, -2) + t[..., None, :]


def add_error(R_pred: Tensor, t_pred: Tensor, R_gt: Tensor, t_gt: Tensor, points: Tensor) -> Tensor:
    """ADD: mean distance between corresponding model points under the two poses."""
    return (_transform(R_pred, t_pred, points) - _transform(R_gt, t_gt, points)).norm(dim=-1).mean(-1)


def adds_error(
    R_pred: Tensor, t_pred: Tensor, R_gt: Tensor, t_gt: Tensor, points: Tensor, max_block: int = 2**22
) -> Tensor:
    """ADD-S: mean over predicted points of the distance to the closest GT-posed point.

    Chunked over the predicted points so that one distance block holds at most `max_block` entries
    (32 MB in float64) whatever the batch size.
    """
    pred, gt = _transform(R_pred, t_pred, points), _transform(R_gt, t_gt, points)
    chunk = max(1, max_block // gt[..., 0].numel())
    nearest = [torch.cdist(pred[..., i : i + chunk, :], gt).amin(-1) for i in range(0, pred.shape[-2], chunk)]
    return torch.cat(nearest, dim=-1).mean(-1)


def esa_score(R_pred: Tensor, t_pred: Tensor, R_gt: Tensor, t_gt: Tensor) -> Tensor:
    """Per-image ESA score e_q (rad) + e_t / |t_gt|, each term zeroed below its threshold."""
    e_q = rotation_error_deg(R_pred, R_gt)
    e_t = translation_error(t_pred, t_gt) / t_gt.norm(dim=-1)
    e_q = torch.where(e_q < ESA_THETA_Q_DEG, torch.zeros_like(e_q), torch.deg2rad(e_q))
    e_t = torch.where(e_t < ESA_THETA_T, torch.zeros_like(e_t), e_t)
    return e_q + e_t


def sample_errors(
    R_pred: Tensor, t_pred: Tensor, R_gt: Tensor, t_gt: Tensor, points: Tensor
) -> dict[str, Tensor]:
    """Every per-sample error, shape (B,) each: re_deg, te_m, add_m, adds_m, esa."""
    args = [x.double() for x in (R_pred, t_pred, R_gt, t_gt)]
    pts = points.double()
    return {
        "re_deg": rotation_error_deg(args[0], args[2]),
        "te_m": translation_error(args[1], args[3]),
        "add_m": add_error(*args, pts),
        "adds_m": adds_error(*args, pts),
        "esa": esa_score(*args),
    }


def summarise(errors: dict[str, list[float]], diameter: float) -> dict[str, float]:
    """Dataset summary: mean re_deg, te_m, esa; recalls add_0.02m, add_0.1d, adds_0.1d in [0, 1]."""
    n = len(errors["re_deg"])

    def recall(key: str, thr: float) -> float:
        return sum(e < thr for e in errors[key]) / n if n else math.nan

    def mean(key: str) -> float:
        return sum(errors[key]) / n if n else math.nan

    return {
        "n": n,
        "re_deg": mean("re_deg"),
        "te_m": mean("te_m"),
        "add_0.02m": recall("add_m", 0.02),
        "add_0.1d": recall("add_m", 0.1 * diameter),
        "adds_0.1d": recall("adds_m", 0.1 * diameter),
        "esa": mean("esa"),
    }
