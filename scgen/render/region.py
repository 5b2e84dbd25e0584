"""The part of the frame a render must trace: the box around every object's projection.

The backends render only the target and the props over a transparent film; the sky, the Earth and the
camera stage's glare and blur are added afterwards in numpy over the full frame. So a pixel whose
samples all miss every object renders as exactly zero (colour, alpha, albedo, normal), and tracing it
only costs time. `covered_region` bounds the pixels any sample can reach an object from: the union of
the objects' projected boxes (convex hulls, so every surface point lies inside), widened by the pixel
filter's reach and a margin for the denoiser's neighbourhood.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from scgen.render.conventions import CLIP_START_M
from scgen.render.props import prop_mesh
from scgen.scenes.geometry import project
from scgen.scenes.spec import SceneSpec

FULL_FRAME_ENV = "SCGEN_FULL_FRAME"  # set to 1: trace the whole frame (the benchmarks' old path), workers too


def region_render() -> bool:
    """Whether renders trace only the covered region (the default) or the whole frame (SCGEN_FULL_FRAME=1)."""
    return os.environ.get(FULL_FRAME_ENV, "") not in ("1", "true", "yes")


@dataclass(frozen=True)
class Region:
    """Pixel columns [x0, x1) and rows [y0, y1) of a width x height frame, rows counted from the top."""

    x0: int
    y0: int
    x1: int
    y1: int
    width: int
    height: int

    @property
    def full(self) -> bool:
        return (self.x0, self.y0, self.x1, self.y1) == (0, 0, self.width, self.height)

    @property
    def window(self) -> tuple[slice, slice]:
        """The region's rows and columns, to index an H x W (x C) array."""
        return np.s_[self.y0 : self.y1, self.x0 : self.x1]

    @property
    def share(self) -> float:
        """The fraction of the frame's pixels inside."""
        return (self.x1 - self.x0) * (self.y1 - self.y0) / (self.width * self.height)

    def paste(self, crop: np.ndarray, fill: float) -> np.ndarray:
        """The full frame holding `crop` (the region's pixels) and `fill` elsewhere."""
        frame = np.full((self.height, self.width, *crop.shape[2:]), fill, crop.dtype)
        frame[self.window] = crop
        return frame


def full_frame(width: int, height: int) -> Region:
    return Region(0, 0, width, height, width, height)


def covered_region(
    K: np.ndarray, width: int, height: int, objects: Iterable[np.ndarray], reach_px: float, margin_px: int
) -> Region:
    """The pixels whose samples may meet one of `objects` (camera-frame points, N x 3, each an object's
    convex hull's vertices, or any points whose hull holds the object), and `margin_px` more on each side.

    A pixel's samples land within `reach_px` of its centre (the pixel filter's half-width; integer
    (u, v) is a pixel centre), so the pixels reached are those whose centre lies within reach_px of an
    object's projected box. An object with a point nearer than the near clip plane may wrap around the
    camera, where its projected box bounds nothing: the whole frame then. No object in view: the whole
    frame too (a renderer cannot render an empty region, and the case is too rare to save anything).
    """
    lo, hi = np.array([np.inf, np.inf]), np.array([-np.inf, -np.inf])
    for points in objects:
        if len(points) == 0:
            continue
        if points[:, 2].min() <= CLIP_START_M:
            return full_frame(width, height)
        uv = project(K, points)
        lo, hi = np.minimum(lo, uv.min(axis=0)), np.maximum(hi, uv.max(axis=0))
    if not np.all(hi >= lo):
        return full_frame(width, height)
    first = [math.ceil(v - reach_px) - margin_px for v in lo]
    last = [math.floor(v + reach_px) + margin_px for v in hi]  # inclusive
    x0, y0 = max(0, first[0]), max(0, first[1])
    x1, y1 = min(width, last[0] + 1), min(height, last[1] + 1)
    if x1 <= x0 or y1 <= y0:
        return full_frame(width, height)
    return Region(x0, y0, x1, y1, width, height)


def scene_region(spec: SceneSpec, hull: np.ndarray, reach_px: float, margin_px: int) -> Region:
    """covered_region of `spec`'s camera (the one rendered) around its target, given as `hull` (the
    vertices of the model's convex hull, model frame), and its props' meshes."""
    cam = spec.camera
    target = hull @ spec.target.R_mat.T + spec.target.t_vec
    objects = [target, *(np.asarray(prop_mesh(p).vertices) for p in spec.props)]
    return covered_region(cam.K_mat, cam.width, cam.height, objects, reach_px, margin_px)
