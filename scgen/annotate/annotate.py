"""Turn renderer Buffers into labels: xyz map (paper eq. 1-2), masks, boxes, occlusion, shadow.

Everything here is pure numpy, so it is tested without any renderer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scgen.io import bop
from scgen.io.buffers import TARGET_ID, Buffers, object_instance_id
from scgen.scenes.factors import occlusion_group, shadow_label
from scgen.scenes.spec import CameraSpec, Pose, SceneSpec

Box = tuple[int, int, int, int]  # x, y, w, h in pixels; may reach past the image
PAIRS_PER_CHUNK = 1 << 18  # (triangle, pixel) tests covered_pixels holds at once (~40 MB)


@dataclass
class Annotation:
    """One sample's labels, inside the image. Boxes are [x, y, w, h] covering pixels x .. x + w - 1
    ([0, 0, 0, 0] when empty); scene_gt_info holds BOP's boxes and counts (`full_projection`)."""

    xyz: np.ndarray  # float32 H x W x 3 model coordinates (metres), zero outside mask_visib
    mask: np.ndarray  # bool, full projected target before external occlusion
    mask_visib: np.ndarray  # bool, visible target pixels
    bbox_obj: list[int]
    bbox_visib: list[int]
    px_count_all: int
    px_count_visib: int
    visib_fract: float
    r_occ: float
    shadow_fraction: float  # the target's; 0 for the other labelled objects (a factor of the target)

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


def full_projection(mask: np.ndarray, camera: CameraSpec, vertices_cam: np.ndarray,
                    faces: np.ndarray) -> tuple[int, list[int]]:  # fmt: skip
    """(px_count_all, bbox_obj) of the target's whole silhouette, measured as bop_toolkit's calc_gt_info
    does: on its canvas reaching one image size past each border (bop.gt_info_canvas), BOP box.

    Inside the image (H x W) the silhouette is `mask` (the renderer's target-alone pass); past the border
    it is the pixel centres covered by the projected triangles (`vertices_cam`: the posed mesh, camera
    frame), which is where a ray cast through them would hit (with a lens: through their projected
    corners, straight-edged). Triangles not wholly in front of the camera are left out: they cannot be
    projected. Only samples the image cuts need the raster.
    """
    H, W = mask.shape
    # every vertex in front and none of their images past the border: no triangle's is (a sixth of the
    # projections: each vertex once, not once per triangle)
    inside = bool((vertices_cam[:, 2] > 0).all()) and not _reach_out(camera.project(vertices_cam), W, H)
    if not inside:
        front = faces[(vertices_cam[faces, 2] > 0).all(axis=1)]
        tri = camera.project(vertices_cam[front.ravel()]).reshape(-1, 3, 2)
        reach_out = _reach_out(tri, W, H)
        inside = not reach_out.any()
    if inside:
        ys, xs = np.nonzero(mask)
        return len(xs), bop.bbox(xs, ys)
    x0, y0, w, h = bop.gt_info_canvas(W, H)
    full = covered_pixels(tri[reach_out], (x0, y0, w, h))
    full[-y0 : -y0 + H, -x0 : -x0 + W] = mask
    ys, xs = np.nonzero(full)
    return len(xs), bop.bbox(xs + x0, ys + y0)


def _reach_out(uv: np.ndarray, W: int, H: int) -> np.ndarray:
    """Whether the pixel centres each point set (..., K, 2: a triangle's corners, or one set N x 2) spans,
    from ceil(min) to floor(max), reach past a W x H image's."""
    lo, hi = np.ceil(uv.min(axis=-2)), np.floor(uv.max(axis=-2))
    return (lo < 0).any(axis=-1) | (hi > [W - 1, H - 1]).any(axis=-1)


def covered_pixels(tri: np.ndarray, box: Box) -> np.ndarray:
    """Which pixels of `box` have their centre inside (or on the edge of) one of the triangles
    (T x 3 x 2, pixel coordinates, centres at integers): h x w bool. Exact, no sub-sampling."""
    x0, y0, w, h = box
    out = np.zeros((h, w), bool)
    lo = np.maximum(np.ceil(tri.min(axis=1)), [x0, y0]).astype(np.int64)
    hi = np.minimum(np.floor(tri.max(axis=1)), [x0 + w - 1, y0 + h - 1]).astype(np.int64)
    keep = (hi >= lo).all(axis=1) & (_cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]) != 0)
    tri, lo, size = tri[keep], lo[keep], (hi - lo + 1)[keep]
    counts = size[:, 0] * size[:, 1]
    for part in _chunks(counts, PAIRS_PER_CHUNK):
        k = np.repeat(part, counts[part])
        j = np.arange(len(k)) - np.repeat(np.cumsum(counts[part]) - counts[part], counts[part])
        u, v = lo[k, 0] + j % size[k, 0], lo[k, 1] + j // size[k, 0]
        inside = _inside(tri[k], np.stack([u, v], axis=1).astype(np.float64))
        out[v[inside] - y0, u[inside] - x0] = True
    return out


def _chunks(counts: np.ndarray, limit: int) -> list[np.ndarray]:
    """Consecutive index runs whose counts add up to about `limit` (one item may exceed it alone)."""
    return np.split(
        np.arange(len(counts)), np.searchsorted(np.cumsum(counts), np.arange(limit, counts.sum(), limit))
    )


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """z of the cross product of 2D vectors (..., 2)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _inside(tri: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Whether each point p (N x 2) lies in its triangle (N x 3 x 2), edges included, either winding."""
    e = np.stack([_cross(tri[:, (i + 1) % 3] - tri[:, i], p - tri[:, i]) for i in range(3)], axis=1)
    return (e >= 0).all(axis=1) | (e <= 0).all(axis=1)


def annotate(spec: SceneSpec, buffers: Buffers) -> Annotation:
    """The target's labels of one rendered sample."""
    ann = instance_annotation(spec, buffers, TARGET_ID, buffers.target_depth, spec.target)
    sun = spec.sun.direction
    ann.shadow_fraction = shadow_fraction(ann.mask_visib, buffers.normal, buffers.sun_blocked, sun)
    return ann


def annotate_objects(spec: SceneSpec, buffers: Buffers) -> tuple[Annotation, ...]:
    """The labels of each of the sample's other labelled objects (SceneSpec.objects), as the target's."""
    return tuple(instance_annotation(spec, buffers, object_instance_id(j), buffers.objects_depth[j], obj.pose)
                 for j, obj in enumerate(spec.objects))  # fmt: skip


def instance_annotation(spec: SceneSpec, buffers: Buffers, instance: int, alone_depth: np.ndarray,
                        pose: Pose) -> Annotation:  # fmt: skip
    """One labelled instance's labels: its full mask (rendered alone), the pixels it is the first hit of,
    its xyz map there; shadow_fraction 0 (annotate sets the target's)."""
    mask = alone_depth > 0
    mask_visib = (buffers.instance == instance) & mask
    xyz = backproject_to_model(buffers.depth, spec.camera, pose.R_mat, pose.t_vec)
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
        shadow_fraction=0.0,
    )


def shadow_fraction(
    mask_visib: np.ndarray, normal: np.ndarray, sun_blocked: np.ndarray, sun_dir: tuple[float, ...]
) -> float:
    """Share of visible target pixels facing the sun whose path to the sun is blocked by another object."""
    facing = mask_visib & (normal @ np.asarray(sun_dir, np.float32) > 0)
    n = int(facing.sum())
    return float((facing & sun_blocked).sum() / n) if n else 0.0
