"""Turn renderer Buffers into labels: xyz map (paper eq. 1-2), masks, boxes, occlusion, shadow.

Everything here is pure numpy, so it is tested without any renderer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scgen.buffers import TARGET_ID, Buffers
from scgen.factors import occlusion_group, shadow_label
from scgen.scenes.spec import CameraSpec, SceneSpec


@dataclass
class Annotation:
    """One sample's labels. Boxes are [x, y, w, h] in pixels ([0, 0, 0, 0] when empty)."""

    xyz: np.ndarray  # float32 H x W x 3 model coordinates (metres), zero outside mask_visib
    mask: np.ndarray  # bool, full projected target before external occlusion
    mask_visib: np.ndarray  # bool, visible target pixels
    bbox_obj: list[int]
    bbox_visib: list[int]
    px_count_all: int
    px_count_visib: int
    visib_fract: float
    r_occ: float
    shadow_fraction: float

    @property
    def occlusion_group(self) -> str:
        return occlusion_group(self.r_occ)

    @property
    def shadow_label(self) -> str:
        return shadow_label(self.shadow_fraction)


def backproject_to_model(depth: np.ndarray, camera: CameraSpec, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """C = R^T (z K^-1 [u, v, 1]^T - t) for every pixel (H x W x 3) of the camera's depth map."""
    x_cam = camera.pixel_rays() * depth[..., None].astype(np.float64)
    return (x_cam - t) @ R  # row-vector form of R^T (x - t)


def mask_bbox(mask: np.ndarray) -> list[int]:
    """[x, y, w, h] of the mask's extent; [0, 0, 0, 0] for an empty mask."""
    ys, xs = np.nonzero(mask)
    if len(xs) == 0:
        return [0, 0, 0, 0]
    return [int(xs.min()), int(ys.min()), int(xs.max() - xs.min() + 1), int(ys.max() - ys.min() + 1)]


def annotate(spec: SceneSpec, buffers: Buffers) -> Annotation:
    """All labels of one rendered sample."""
    mask = buffers.target_depth > 0
    mask_visib = (buffers.instance == TARGET_ID) & mask
    xyz = backproject_to_model(buffers.depth, spec.camera, spec.target.R_mat, spec.target.t_vec)
    xyz = np.where(mask_visib[..., None], xyz, 0.0).astype(np.float32)
    n_all = int(mask.sum())
    n_vis = int(mask_visib.sum())
    visib = n_vis / n_all if n_all else 0.0
    return Annotation(
        xyz=xyz,
        mask=mask,
        mask_visib=mask_visib,
        bbox_obj=mask_bbox(mask),
        bbox_visib=mask_bbox(mask_visib),
        px_count_all=n_all,
        px_count_visib=n_vis,
        visib_fract=float(visib),
        r_occ=float(1.0 - visib) if n_all else 1.0,
        shadow_fraction=shadow_fraction(mask_visib, buffers.normal, buffers.sun_blocked, spec.sun.direction),
    )


def shadow_fraction(
    mask_visib: np.ndarray, normal: np.ndarray, sun_blocked: np.ndarray, sun_dir: tuple[float, ...]
) -> float:
    """Share of visible target pixels facing the sun whose path to the sun is blocked by another object."""
    facing = mask_visib & (normal @ np.asarray(sun_dir, np.float32) > 0)
    n = int(facing.sum())
    return float((facing & sun_blocked).sum() / n) if n else 0.0
