"""A pose's confidence from the network's own two answers: the share of the pixels of its predicted
visible mask whose predicted model point (the xyz head) the decoded pose (Patch-PnP) projects back within
one output cell. 1 where both heads tell one story, near 0 where they disagree (a black frame in eclipse,
a crop without the target). predict flags a pose under LOW_CONFIDENCE; the navigation filter reads its
measurement covariance from it (posenet.navigation.noise). One home for predict's and eval's figure.
"""

from __future__ import annotations

import numpy as np
import torch

from posenet.data.camera import Camera, project
from posenet.geometry import mask_probability
from posenet.predict.ransac import MIN_POINTS, correspondences


def pose_confidence(
    xyz: np.ndarray,
    visible: np.ndarray,
    extent: np.ndarray,
    center: np.ndarray,
    scale: float,
    R: np.ndarray,
    t: np.ndarray,
    camera: Camera,
) -> float:
    """The confidence of pose (R, t) decoded from one RoI (centre `center`, side `scale` in image pixels)
    whose heads gave normalised xyz (3 x r x r) and the visible mask (r x r bool), in `camera`."""
    points, pixels = correspondences(xyz, visible, extent, center, scale)
    if len(points) < MIN_POINTS:
        return 0.0
    error = np.linalg.norm(project(points, R, t, camera) - pixels, axis=1)
    return float(np.mean(error <= scale / visible.shape[0]))


def batch_confidences(
    out: dict[str, torch.Tensor],
    roi: dict[str, torch.Tensor],
    R: torch.Tensor,
    t: torch.Tensor,
    extent: np.ndarray,
    mask_type: str,
    cameras: list[Camera],
) -> list[float]:
    """`pose_confidence` of each RoI of a batch (its `crop_center` and `resize_ratio`) at its pose."""
    visible = (mask_probability(out["mask"].float(), mask_type)[:, 0] > 0.5).cpu().numpy()
    xyz = out["xyz"].float().cpu().numpy()
    centre = roi["crop_center"].double().cpu().numpy()
    scale = (visible.shape[-1] / roi["resize_ratio"].double()).cpu().numpy()
    R, t = R.double().cpu().numpy(), t.double().cpu().numpy()
    return [
        pose_confidence(xyz[i], visible[i], extent, centre[i], float(scale[i]), R[i], t[i], cameras[i])
        for i in range(len(xyz))
    ]
