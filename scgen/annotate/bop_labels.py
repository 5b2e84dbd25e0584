"""Labels of one instance of a BOP image from ray-cast buffers: full and visible masks, xyz crop, gt_info.

Pure numpy, with the conventions and helpers of `annotate`: xyz = Rᵀ(z·K⁻¹p̄ − t) on the visible pixels,
boxes by `mask_bbox`. The full projection is counted on a canvas that may extend past the image.
Where the dataset has its own mask_visib, that mask is the authority: the ray cast only holds the objects
scene_gt lists, so occluders it does not list would otherwise leave xyz on pixels they hide.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from scgen.annotate.annotate import backproject_to_model, mask_bbox
from scgen.io import bop
from scgen.scenes.projection import Box
from scgen.scenes.spec import CameraSpec


@dataclass(frozen=True)
class VisibDisagreement:
    """Pixels where the ray cast's visibility and the dataset's own mask_visib differ; no xyz on either.
    Zero where the dataset has no mask_visib (annotate writes the ray cast's)."""

    cast_only: int = 0  # the ray cast sees the instance, mask_visib hides it: occluders scene_gt omits
    mask_only: int = 0  # mask_visib shows it, the ray cast finds a listed instance in front or no model

    def __add__(self, other: VisibDisagreement) -> VisibDisagreement:
        return VisibDisagreement(self.cast_only + other.cast_only, self.mask_only + other.mask_only)


@dataclass
class InstanceLabels:
    mask: np.ndarray  # bool H x W: the instance alone (before occlusion), inside the image
    mask_visib: np.ndarray  # bool H x W: pixels where it is the first surface hit
    xyz: np.ndarray | None  # float32 crop to gt_info["xyz_box"], metres, zero outside both visible masks
    gt_info: dict[str, Any]  # the scene_gt_info.json entry, visibility from the dataset's mask_visib if any
    disagreement: VisibDisagreement


def inside_image(full: np.ndarray, box: Box, size: tuple[int, int]) -> np.ndarray:
    """The image-sized (W, H = size) part of a mask cast over `box`."""
    x, y, w, h = box
    out = np.zeros((size[1], size[0]), bool)
    x0, y0, x1, y1 = max(x, 0), max(y, 0), min(x + w, size[0]), min(y + h, size[1])
    if x0 < x1 and y0 < y1:
        out[y0:y1, x0:x1] = full[y0 - y : y1 - y, x0 - x : x1 - x]
    return out


def instance_labels(k: int, index: np.ndarray, depth: np.ndarray, full: np.ndarray, box: Box,
                    camera: CameraSpec, R: np.ndarray, t: np.ndarray,
                    own_visib: np.ndarray | None) -> InstanceLabels:  # fmt: skip
    """Instance k's labels from the cast of every instance over the image (first-hit `index`, `depth`),
    the cast of instance k alone over `box` (`full`, its hit mask there) and the dataset's own mask_visib
    of the instance (None: it has none). xyz is kept where both the ray cast and that mask see it."""
    mask = inside_image(full, box, (camera.width, camera.height))
    mask_visib = (index == k) & mask
    visib = mask_visib if own_visib is None else own_visib
    seen = visib & mask_visib
    disagreement = VisibDisagreement(int((mask_visib & ~visib).sum()), int((visib & ~mask_visib).sum()))
    ys, xs = np.nonzero(full)
    bbox_obj = bop.bbox(xs + box[0], ys + box[1])
    xyz_box = mask_bbox(seen) if seen.any() else None
    # no depth is read: px_count_valid counts the silhouette inside the image
    info = bop.gt_info_entry(int(full.sum()), bbox_obj, visib, int(mask.sum()), xyz_box)
    if xyz_box is None:
        return InstanceLabels(mask, mask_visib, None, info, disagreement)
    x, y, w, h = xyz_box
    xyz = np.where(seen[..., None], backproject_to_model(depth, camera, R, t), 0.0)
    return InstanceLabels(mask, mask_visib, xyz[y : y + h, x : x + w].astype(np.float32), info, disagreement)
