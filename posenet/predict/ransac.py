"""PnP-RANSAC on the predicted dense correspondences: GDR-Net's ablation row beside Patch-PnP.

For each RoI, the pixels the predicted visible mask holds give 2D-3D pairs: the RoI pixel centre mapped
back to image coordinates, and the predicted xyz turned into model coordinates (metres). OpenCV's
solvePnPRansac (EPnP in each hypothesis, then a refinement on the inliers) solves them with the image's
K. An evaluation option only: training never sees it.
"""

from __future__ import annotations

import cv2
import numpy as np
import torch
from torch import Tensor

from posenet.data.crop import roi_pixel_centres
from posenet.geometry import mask_probability

PNP_METHODS = ("patch", "ransac")
PNP_LABELS = {"patch": "Patch-PnP", "ransac": "PnP-RANSAC"}
RANSAC_PX = 2.0  # inlier threshold: reprojection error in image pixels
RANSAC_ITERS = 100  # hypotheses (OpenCV's default)
MIN_POINTS = 6  # fewer predicted visible pixels than this: no pose


def ransac_pose(
    points: np.ndarray, pixels: np.ndarray, K: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """(R, t) of model points (N x 3, metres) seen at image pixels (N x 2) by K, or None where too few
    points or RANSAC finds no pose."""
    if len(points) < MIN_POINTS:
        return None
    ok, rvec, tvec, _ = cv2.solvePnPRansac(
        points.astype(np.float64),
        pixels.astype(np.float64),
        K.astype(np.float64),
        None,
        iterationsCount=RANSAC_ITERS,
        reprojectionError=RANSAC_PX,
        confidence=0.99,
        flags=cv2.SOLVEPNP_EPNP,
    )
    if not ok:
        return None
    return cv2.Rodrigues(rvec)[0], tvec[:, 0]


def correspondences(
    xyz: np.ndarray, visible: np.ndarray, extent: np.ndarray, center: np.ndarray, scale: float
) -> tuple[np.ndarray, np.ndarray]:
    """(model points N x 3 in metres, image pixels N x 2) of one RoI: the predicted normalised xyz
    (3 x r x r, xyz / extent + 0.5) at the pixels where `visible` (r x r bool) holds."""
    u, v = roi_pixel_centres(center, scale, visible.shape[0])
    rows, cols = np.nonzero(visible)
    points = (xyz[:, rows, cols].T - 0.5) * extent
    return points, np.stack([u[cols], v[rows]], 1)


def ransac_poses(
    out: dict[str, Tensor], roi: dict[str, Tensor], extent: np.ndarray, mask_type: str
) -> tuple[Tensor, Tensor, Tensor]:
    """(R B x 3 x 3, t B x 3, solved B bool) of a batch's network outputs and RoI geometry (`K`,
    `crop_center`, `resize_ratio`); an unsolved RoI has the identity and a zero translation."""
    visible = (mask_probability(out["mask"].float(), mask_type)[:, 0] > 0.5).cpu().numpy()
    xyz = out["xyz"].float().cpu().numpy()
    K, centre = roi["K"].cpu().numpy(), roi["crop_center"].cpu().numpy()
    scale = (visible.shape[-1] / roi["resize_ratio"]).cpu().numpy()  # RoI side in image pixels
    R, t, solved = np.tile(np.eye(3), (len(xyz), 1, 1)), np.zeros((len(xyz), 3)), np.zeros(len(xyz), bool)
    for i in range(len(xyz)):
        pose = ransac_pose(*correspondences(xyz[i], visible[i], extent, centre[i], float(scale[i])), K[i])
        if pose is not None:
            R[i], t[i], solved[i] = pose[0], pose[1], True
    device = out["xyz"].device
    return (
        torch.from_numpy(R).float().to(device),
        torch.from_numpy(t).float().to(device),
        torch.from_numpy(solved).to(device),
    )
