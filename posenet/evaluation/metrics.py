"""Pose metrics per sample (batched torch, float64) and their dataset summary.

Rotation / translation error (the rotation error also as the minimum over the GT's symmetric poses), ADD
and ADD-S (BOP's ADD / ADI), MSSD (BOP19), and the ESA (SPEC) score with the SPEC2021 calibration-precision
thresholds applied independently to each term, as in SPNv2.
"""

from __future__ import annotations

import math
import statistics
from typing import Any

import torch
from torch import Tensor

from posenet.geometry import symmetric_poses

TURNED_DEG = 135.0  # a rotation error beyond this is a turned pose (the bundled target's near-D2 symmetry)
ESA_THETA_Q_DEG = 0.169  # rotation errors below this count as 0 (SPEC2021 / SPEED+ HIL)
ESA_THETA_T = 2.173e-3  # normalised translation errors below this (2.173 mm per metre) count as 0
MSSD_THRESHOLDS = tuple(0.05 * k for k in range(1, 11))  # BOP19's AR_MSSD: 0.05..0.5 of the diameter


def rotation_error_deg(R_pred: Tensor, R_gt: Tensor) -> Tensor:
    """arccos((tr(R_pred^T R_gt) - 1) / 2) in degrees."""
    cos = ((R_pred.transpose(-1, -2) @ R_gt).diagonal(dim1=-2, dim2=-1).sum(-1) - 1.0) / 2.0
    return torch.rad2deg(torch.arccos(cos.clamp(-1.0, 1.0)))


def rotation_error_sym_deg(R_pred: Tensor, R_gt: Tensor, t_gt: Tensor, symmetries: Tensor) -> Tensor:
    """The smallest rotation error (degrees) to any of the GT's symmetric poses ((K, 4, 4) `symmetries`)."""
    R_sym, _ = symmetric_poses(R_gt, t_gt, symmetries)
    return rotation_error_deg(R_pred[..., None, :, :], R_sym).amin(-1)


def translation_error(t_pred: Tensor, t_gt: Tensor) -> Tensor:
    """Euclidean distance between translations (metres)."""
    return (t_pred - t_gt).norm(dim=-1)


def _transform(R: Tensor, t: Tensor, points: Tensor) -> Tensor:
    return points @ R.transpose(-1, -2) + t[..., None, :]


def depth_error_rel(t_pred: Tensor, t_gt: Tensor) -> Tensor:
    """|t_z - t_z_gt| / t_z_gt: the depth error as a share of the depth (what scale in pixels fixes)."""
    return (t_pred[..., 2] - t_gt[..., 2]).abs() / t_gt[..., 2]


def add_error(R_pred: Tensor, t_pred: Tensor, R_gt: Tensor, t_gt: Tensor, points: Tensor) -> Tensor:
    """ADD: mean distance between corresponding model points under the two poses."""
    return (_transform(R_pred, t_pred, points) - _transform(R_gt, t_gt, points)).norm(dim=-1).mean(-1)


def adds_error(
    R_pred: Tensor, t_pred: Tensor, R_gt: Tensor, t_gt: Tensor, points: Tensor, max_block: int = 2**22
) -> Tensor:
    """ADD-S as BOP's ADI (bop_toolkit's pose_error.adi): mean over the GT-posed points of the distance to
    the closest point of the predicted pose.

    Chunked over the GT points so that one distance block holds at most `max_block` entries (32 MB in
    float64) whatever the batch size.
    """
    pred, gt = _transform(R_pred, t_pred, points), _transform(R_gt, t_gt, points)
    chunk = max(1, max_block // pred[..., 0].numel())
    nearest = [torch.cdist(gt[..., i : i + chunk, :], pred).amin(-1) for i in range(0, gt.shape[-2], chunk)]
    return torch.cat(nearest, dim=-1).mean(-1)


def mssd_error(
    R_pred: Tensor,
    t_pred: Tensor,
    R_gt: Tensor,
    t_gt: Tensor,
    vertices: Tensor,
    symmetries: Tensor,
    max_block: int = 2**22,
) -> Tensor:
    """MSSD (BOP19): over the GT's symmetric poses, the smallest largest distance between a model vertex
    under the predicted pose and under that pose.

    A distance's maximum over a mesh lies at a vertex, so the vertices give the surface's exact maximum.
    Chunked over the symmetries so that one block holds at most `max_block` coordinates.
    """
    R_sym, t_sym = symmetric_poses(R_gt, t_gt, symmetries)
    dR, dt = R_pred[..., None, :, :] - R_sym, t_pred[..., None, :] - t_sym  # (R_e - R_s) x + (t_e - t_s)
    chunk = max(1, max_block // (dR[..., 0, 0, 0].numel() * vertices.numel()))  # symmetries per block
    worst = [
        (vertices @ r.transpose(-1, -2) + d[..., None, :]).norm(dim=-1).amax(-1)
        for r, d in zip(dR.split(chunk, dim=-3), dt.split(chunk, dim=-2), strict=True)
    ]
    return torch.cat(worst, dim=-1).amin(-1)


def esa_score(R_pred: Tensor, t_pred: Tensor, R_gt: Tensor, t_gt: Tensor) -> Tensor:
    """Per-image ESA score e_q (rad) + e_t / |t_gt|, each term zeroed below its threshold."""
    e_q = rotation_error_deg(R_pred, R_gt)
    e_t = translation_error(t_pred, t_gt) / t_gt.norm(dim=-1)
    e_q = torch.where(e_q < ESA_THETA_Q_DEG, torch.zeros_like(e_q), torch.deg2rad(e_q))
    e_t = torch.where(e_t < ESA_THETA_T, torch.zeros_like(e_t), e_t)
    return e_q + e_t


def sample_errors(
    R_pred: Tensor,
    t_pred: Tensor,
    R_gt: Tensor,
    t_gt: Tensor,
    points: Tensor,
    vertices: Tensor,
    symmetries: Tensor,
) -> dict[str, Tensor]:
    """Every per-sample error, shape (B,) each: re_deg, re_sym_deg, te_m, tz_rel, add_m, add_rot_m, adds_m,
    mssd_m, esa.

    ADD and ADD-S use the surface `points`, MSSD the model `vertices`; re_sym_deg and MSSD the object's
    (K, 4, 4) `symmetries` (K = 1: re_sym_deg = re_deg). ADD splits into its two causes: add_rot_m is the
    ADD of the predicted rotation at the GT translation, and te_m is the ADD of the predicted translation
    at the GT rotation (every point moves by the same offset).
    """
    args = [x.double() for x in (R_pred, t_pred, R_gt, t_gt)]
    pts, verts, syms = points.double(), vertices.double(), symmetries.double()
    return {
        "re_deg": rotation_error_deg(args[0], args[2]),
        "re_sym_deg": rotation_error_sym_deg(args[0], args[2], args[3], syms),
        "te_m": translation_error(args[1], args[3]),
        "tz_rel": depth_error_rel(args[1], args[3]),
        "add_m": add_error(*args, pts),
        "add_rot_m": add_error(args[0], args[3], args[2], args[3], pts),
        "adds_m": adds_error(*args, pts),
        "mssd_m": mssd_error(*args, verts, syms),
        "esa": esa_score(*args),
    }


def headline_add(symmetric: bool) -> tuple[str, str]:
    """(error key, name) of the headline ADD: ADD-S for a symmetric object, else ADD (GDR-Net's ADD(-S) on
    LINEMOD, BOP's `ad` error)."""
    return ("adds_m", "ADD-S") if symmetric else ("add_m", "ADD")


def summarise(errors: dict[str, list[float]], diameter: float, symmetric: bool) -> dict[str, Any]:
    """Dataset summary: mean re_deg, re_sym_deg, te_m, esa; recalls in [0, 1]: add_0.02m and add_0.1d of
    the headline ADD (`add_metric`, see headline_add), adds_0.1d, mssd_0.1d, BOP19's ar_mssd (MSSD's
    recall averaged over MSSD_THRESHOLDS), and ADD@0.1d of the rotation alone (add_rot_0.1d, at the GT
    translation) and of the translation alone (te_0.1d, at the GT rotation): which of the two fails ADD;
    medians of the rotation, translation and relative depth errors (re_deg_median, te_m_median,
    tz_rel_median) and the share of turned poses (`turned`: rotation error beyond TURNED_DEG).

    An instance without an estimate (a missed detection) has infinite errors: it fails every recall, and
    the means, medians and the turned share are over the estimated instances only (nan when there is none).
    """
    n = len(errors["re_deg"])
    add_key, add_name = headline_add(symmetric)

    def recall(key: str, thr: float) -> float:
        return sum(e < thr for e in errors[key]) / n if n else math.nan

    def finite(key: str) -> list[float]:
        return [e for e in errors[key] if math.isfinite(e)]

    def mean(key: str) -> float:
        values = finite(key)
        return sum(values) / len(values) if values else math.nan

    def median(key: str) -> float:
        values = finite(key)
        return statistics.median(values) if values else math.nan

    rotations = finite("re_deg")

    return {
        "n": n,
        "re_deg": mean("re_deg"),
        "re_sym_deg": mean("re_sym_deg"),
        "te_m": mean("te_m"),
        "symmetric": symmetric,
        "add_metric": add_name,
        "add_0.02m": recall(add_key, 0.02),
        "add_0.1d": recall(add_key, 0.1 * diameter),
        "adds_0.1d": recall("adds_m", 0.1 * diameter),
        "mssd_0.1d": recall("mssd_m", 0.1 * diameter),
        "add_rot_0.1d": recall("add_rot_m", 0.1 * diameter),
        "te_0.1d": recall("te_m", 0.1 * diameter),
        "ar_mssd": sum(recall("mssd_m", f * diameter) for f in MSSD_THRESHOLDS) / len(MSSD_THRESHOLDS),
        "esa": mean("esa"),
        "re_deg_median": median("re_deg"),
        "te_m_median": median("te_m"),
        "tz_rel_median": median("tz_rel"),
        "turned": sum(e > TURNED_DEG for e in rotations) / len(rotations) if rotations else math.nan,
    }
