"""Pose geometry as pure, batched, differentiable torch functions.

Conventions: OpenCV camera (x right, y down, z forward), X_cam = R @ X_model + t, K in pixels,
pixel (u, v) is the centre of column u, row v. Leading dimensions are batch dimensions.
"""

from __future__ import annotations

import torch
from torch import Tensor


def rot6d_to_mat(d6: Tensor) -> Tensor:
    """6D rotation (first two columns, unnormalised) -> rotation matrix by Gram-Schmidt, R = [x y z]."""
    x = torch.nn.functional.normalize(d6[..., 0:3], dim=-1)
    z = torch.nn.functional.normalize(torch.cross(x, d6[..., 3:6], dim=-1), dim=-1)
    y = torch.cross(z, x, dim=-1)
    return torch.stack((x, y, z), dim=-1)


def mat_to_rot6d(R: Tensor) -> Tensor:
    """Rotation matrix -> its 6D representation (first column, then second column)."""
    return torch.cat((R[..., :, 0], R[..., :, 1]), dim=-1)


def ray_rotation(t: Tensor) -> Tensor:
    """R_q: the rotation taking the optical axis (0, 0, 1) onto the ray towards t (Rodrigues, no branch).

    With v = z x t_hat and c = t_hat_z: R_q = I + [v]x + [v]x^2 / (1 + c); defined for any t in front of
    the camera (c > -1), exact identity on the optical axis.
    """
    t_hat = torch.nn.functional.normalize(t, dim=-1)
    zero = torch.zeros_like(t_hat[..., 0])
    vx, vy = -t_hat[..., 1], t_hat[..., 0]  # (0, 0, 1) x t_hat, whose z component is 0
    skew = torch.stack(
        (
            torch.stack((zero, zero, vy), dim=-1),
            torch.stack((zero, zero, -vx), dim=-1),
            torch.stack((-vy, vx, zero), dim=-1),
        ),
        dim=-2,
    )
    eye = torch.eye(3, dtype=t.dtype, device=t.device).expand_as(skew)
    return eye + skew + skew @ skew / (1.0 + t_hat[..., 2])[..., None, None]


def allo_to_ego(R_allo: Tensor, t: Tensor) -> Tensor:
    """Allocentric rotation (as seen along the ray to t) -> egocentric (camera-frame) rotation."""
    return ray_rotation(t) @ R_allo


def ego_to_allo(R_ego: Tensor, t: Tensor) -> Tensor:
    """Egocentric rotation -> allocentric: the inverse of allo_to_ego for the same t."""
    return ray_rotation(t).transpose(-1, -2) @ R_ego


def project(K: Tensor, X: Tensor) -> Tensor:
    """Pinhole projection of camera-frame points X (..., 3) with K (..., 3, 3) -> pixels (..., 2)."""
    uvw = (K @ X.unsqueeze(-1)).squeeze(-1)
    return uvw[..., :2] / uvw[..., 2:3]


def site_encode(t: Tensor, K: Tensor, crop_center: Tensor, box_wh: Tensor, resize_ratio: Tensor) -> Tensor:
    """SITE target (dx, dy, z_ratio) of translation t for a RoI.

    dx, dy: offset of the projected object centre from the crop centre in units of the (un-padded) box
    size; z_ratio = t_z / resize_ratio, where resize_ratio = output_res / crop_scale (zoom-invariant depth).
    """
    offset = (project(K, t) - crop_center) / box_wh
    return torch.cat((offset, (t[..., 2] / resize_ratio)[..., None]), dim=-1)


def site_decode(site: Tensor, K: Tensor, crop_center: Tensor, box_wh: Tensor, resize_ratio: Tensor) -> Tensor:
    """Translation t from SITE (dx, dy, z_ratio): the inverse of site_encode (differentiable)."""
    centre = site[..., :2] * box_wh + crop_center
    tz = site[..., 2] * resize_ratio
    tx = tz * (centre[..., 0] - K[..., 0, 2]) / K[..., 0, 0]
    ty = tz * (centre[..., 1] - K[..., 1, 2]) / K[..., 1, 1]
    return torch.stack((tx, ty, tz), dim=-1)


def roi_translation(site: Tensor, roi: dict[str, Tensor]) -> Tensor:
    """Translation t of SITE `site` in the RoI geometry of a dataset item or batch `roi` (its `K`,
    `crop_center`, `box_wh` and `resize_ratio`)."""
    return site_decode(site, roi["K"], roi["crop_center"], roi["box_wh"], roi["resize_ratio"])


def symmetric_poses(R: Tensor, t: Tensor, symmetries: Tensor) -> tuple[Tensor, Tensor]:
    """Every pose showing the same view of the object as (R, t): (R·S_R, R·S_t + t) for each of its (K, 4, 4)
    symmetry transforms S (model frame, identity included); shapes (..., K, 3, 3) and (..., K, 3)."""
    R_k = R[..., None, :, :]
    return R_k @ symmetries[:, :3, :3], (R_k @ symmetries[:, :3, 3:]).squeeze(-1) + t[..., None, :]


def decode_pose(out: dict[str, Tensor], roi: dict[str, Tensor]) -> tuple[Tensor, Tensor]:
    """Egocentric (R, t) from network outputs (allocentric `rot6d`, `site`) and a batch's RoI geometry
    (`K`, `crop_center`, `box_wh`, `resize_ratio`)."""
    t = roi_translation(out["site"], roi)
    return allo_to_ego(rot6d_to_mat(out["rot6d"]), t), t


def mask_probability(mask: Tensor, kind: str) -> Tensor:
    """The visible-mask probability that a mask channel trained with loss `kind` stands for: the sigmoid
    of a logit ('bce'), the raw value clipped to [0, 1] ('l1')."""
    return mask.sigmoid() if kind == "bce" else mask.clamp(0.0, 1.0)
