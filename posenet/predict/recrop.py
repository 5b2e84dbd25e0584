"""Re-crop from the network's own estimate: the box of the object model projected at a pose.

The pose network trains and evaluates on crops around `bbox_obj`, the box of the object's whole
silhouette (the pixel centres it covers, possibly past the image's border). The same box at a decoded
pose is the extent of the projected mesh vertices, rounded inwards to pixel centres: the silhouette is
the projected triangles, whose extreme points are vertices. A second pass then crops the image as
training did around the true box, whatever box started the first (CosyPose/MegaPose re-crop around the
current pose every refiner iteration; Pix2Pose around its own mask).
"""

from __future__ import annotations

import numpy as np

from posenet.data.boxes import Box, clip_box
from posenet.data.camera import Camera, project
from posenet.data.object_model import ObjectModel


def projected_box(vertices: np.ndarray, R: np.ndarray, t: np.ndarray, camera: Camera) -> Box | None:
    """`bbox_obj` of the model (`vertices`, N x 3, metres) at pose (R, t) seen by `camera`: the pixel
    centres its projection spans, unclipped, as scgen annotates it; None when a vertex is not in front
    of the camera (no projection) or the box covers no pixel centre."""
    if np.any(np.asarray(vertices) @ np.asarray(R).T[:, 2] + t[2] <= 0):
        return None
    uv = project(vertices, R, t, camera)
    (u0, v0), (u1, v1) = np.ceil(uv.min(0)), np.floor(uv.max(0))
    if u1 < u0 or v1 < v0:
        return None
    return float(u0), float(v0), float(u1 - u0 + 1), float(v1 - v0 + 1)


def model_box(obj: ObjectModel, R: np.ndarray, t: np.ndarray, camera: Camera) -> Box | None:
    """`projected_box` of the object at (R, t): through a pinhole, of its convex hull's vertices alone,
    the same box (a projective map keeps the points in front of the camera convex, and the box of a set is
    the box of its hull's extreme points; one is behind the camera exactly when a hull vertex is), ~50x
    quicker for the bundled model; through a lens, of every vertex."""
    return projected_box(obj.vertices if camera.distorted else obj.hull, R, t, camera)


def next_crop(obj: ObjectModel, R: np.ndarray, t: np.ndarray, camera: Camera, box: Box,
              same_iou: float) -> Box | None:  # fmt: skip
    """The box the pass after one that cropped around `box` and decoded (R, t) crops around: the model's
    box at (R, t). None where no pass follows and (R, t) stands: the pose projects to no box, or its box
    overlaps `box` by `same_iou` or more (IoU), so the next pass would see what this one saw and decode
    its translation against a box of the same size. A `same_iou` of 1 gates nothing: every pass runs."""
    again = model_box(obj, R, t, camera)
    return None if again is None or (same_iou < 1.0 and box_iou(again, box) >= same_iou) else again


def box_iou(a: Box, b: Box) -> float:
    """IoU of two boxes [x, y, w, h] (pixels x .. x + w - 1: each pixel counts whole)."""
    w = min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0])
    h = min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1])
    inter = max(w, 0.0) * max(h, 0.0)
    union = a[2] * a[3] + b[2] * b[3] - inter
    return inter / union if union > 0 else 0.0


def in_view(box: Box, size: tuple[int, int], min_share: float) -> bool:
    """Whether at least `min_share` of `box`'s area lies in an image of `size` (a track losing its target
    leaves the view)."""
    inside = clip_box(box, size)
    return inside is not None and inside[2] * inside[3] >= min_share * box[2] * box[3]
