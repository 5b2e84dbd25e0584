"""The part of the frame a render must trace: the boxes around the objects' projections.

The backends render only the target and the props over a transparent film; the sky, the Earth and the
camera stage's glare and blur are added afterwards in numpy over the full frame. So a pixel whose
samples all miss every object renders as exactly zero (colour, alpha, albedo, normal), and tracing it
only costs time. `covered_region` bounds the pixels any sample can reach an object from: the union of
the objects' projected boxes (convex hulls, so every surface point lies inside), widened by the pixel
filter's reach and a margin (a denoiser's view of the objects' surroundings, where a backend wants one;
Blender's measured none); `covered_regions` bounds the same pixels as disjoint boxes, one per object or
group of overlapping objects, for a renderer that can trace several (Blender: one border per render
call; Mitsuba compiles its film's size, so it traces one window).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from scgen.io.bop import TARGET_OBJ_ID
from scgen.render.conventions import CLIP_START_M
from scgen.render.objects import object_hulls
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

    def overlaps(self, other: Region) -> bool:
        """Whether the two share a pixel."""
        return self.x0 < other.x1 and other.x0 < self.x1 and self.y0 < other.y1 and other.y0 < self.y1

    def around(self, other: Region) -> Region:
        """The smallest region holding both."""
        return Region(min(self.x0, other.x0), min(self.y0, other.y0), max(self.x1, other.x1),
                      max(self.y1, other.y1), self.width, self.height)  # fmt: skip

    def paste(self, crop: np.ndarray, fill: float) -> np.ndarray:
        """The full frame holding `crop` (the region's pixels) and `fill` elsewhere."""
        return paste((self,), (crop,), fill)


def paste(regions: Sequence[Region], crops: Sequence[np.ndarray], fill: float) -> np.ndarray:
    """The full frame holding each crop in its region (disjoint regions of one frame), `fill` elsewhere."""
    first = regions[0]
    frame = np.full((first.height, first.width, *crops[0].shape[2:]), fill, crops[0].dtype)
    for region, crop in zip(regions, crops, strict=True):
        frame[region.window] = crop
    return frame


def traced_share(regions: Iterable[Region]) -> float:
    """The fraction of the frame's pixels inside disjoint `regions`."""
    return sum(r.share for r in regions)


def full_frame(width: int, height: int) -> Region:
    return Region(0, 0, width, height, width, height)


def covered_region(
    K: np.ndarray, width: int, height: int, objects: Iterable[np.ndarray], reach_px: float, margin_px: int
) -> Region:
    """The pixels whose samples may meet one of `objects` (camera-frame points, N x 3, each an object's
    convex hull's vertices, or any points whose hull holds the object), and `margin_px` more on each side.

    A pixel's samples land within `reach_px` of its centre (the pixel filter's reach; integer
    (u, v) is a pixel centre), so the pixels reached are those whose centre lies within reach_px of an
    object's projected box. An object with a point nearer than the near clip plane may wrap around the
    camera, where its projected box bounds nothing: the whole frame then. No object in view: the whole
    frame too (a renderer cannot render an empty region, and the case is too rare to save anything).
    """
    boxes = projected_boxes(K, objects)
    if boxes is None or not boxes:
        return full_frame(width, height)
    lo, hi = np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)
    return widened(lo, hi, reach_px, margin_px, width, height) or full_frame(width, height)


def covered_regions(
    K: np.ndarray, width: int, height: int, objects: Iterable[np.ndarray], reach_px: float, margin_px: int
) -> tuple[Region, ...]:
    """The pixels whose samples may meet one of `objects`, as covered_region's, but as disjoint regions:
    each object's own widened box, boxes that overlap merged into the box around both until none do.
    Far-apart objects (a target and an occluder at the other side of the frame) so leave the empty pixels
    between them untraced. The same whole-frame cases as covered_region; an object out of view adds
    nothing."""
    boxes = projected_boxes(K, objects)
    if boxes is None:
        return (full_frame(width, height),)
    regions = [r for lo, hi in boxes if (r := widened(lo, hi, reach_px, margin_px, width, height))]
    return disjoint(regions) if regions else (full_frame(width, height),)


def projected_boxes(
    K: np.ndarray, objects: Iterable[np.ndarray]
) -> list[tuple[np.ndarray, np.ndarray]] | None:
    """Each non-empty object's projected box, (min (u, v), max (u, v)); None when an object reaches the
    near clip plane (its projection may wrap around the camera and bound nothing)."""
    boxes = []
    for points in objects:
        if len(points) == 0:
            continue
        if points[:, 2].min() <= CLIP_START_M:
            return None
        uv = project(K, points)
        boxes.append((uv.min(axis=0), uv.max(axis=0)))
    return boxes


def widened(
    lo: np.ndarray, hi: np.ndarray, reach_px: float, margin_px: int, width: int, height: int
) -> Region | None:
    """The pixels whose centre lies within reach_px of the box [lo, hi], margin_px more on each side,
    inside the frame; None when none of them is."""
    first = [math.ceil(v - reach_px) - margin_px for v in lo]
    last = [math.floor(v + reach_px) + margin_px for v in hi]  # inclusive
    x0, y0 = max(0, first[0]), max(0, first[1])
    x1, y1 = min(width, last[0] + 1), min(height, last[1] + 1)
    if x1 <= x0 or y1 <= y0:
        return None
    return Region(x0, y0, x1, y1, width, height)


def disjoint(regions: list[Region]) -> tuple[Region, ...]:
    """`regions` with every overlapping pair replaced by the box around both, until no two overlap."""
    merged = list(regions)
    while True:
        pair = next(((i, j) for i in range(len(merged)) for j in range(i + 1, len(merged))
                     if merged[i].overlaps(merged[j])), None)  # fmt: skip
        if pair is None:
            return tuple(merged)
        b = merged.pop(pair[1])
        merged[pair[0]] = merged[pair[0]].around(b)


def holding(regions: Sequence[Region], part: Region) -> tuple[Region, ...]:
    """The regions that share a pixel with `part`: where disjoint regions were merged from boxes (as
    covered_regions'), the one holding a box that was among them, or every region for the whole frame."""
    return tuple(r for r in regions if r.overlaps(part))


def target_region(
    spec: SceneSpec, hulls: Mapping[int, np.ndarray], reach_px: float, margin_px: int
) -> Region:
    """covered_region of `spec`'s camera around the target alone (the whole frame when it is out of view)."""
    cam = spec.camera
    return covered_region(cam.K_mat, cam.width, cam.height, [target_hull(spec, hulls)], reach_px, margin_px)


def target_hull(spec: SceneSpec, hulls: Mapping[int, np.ndarray]) -> np.ndarray:
    """The target's convex hull vertices (`hulls`' OBJ_ID entry, model frame) in `spec`'s camera frame."""
    return hulls[TARGET_OBJ_ID] @ spec.target.R_mat.T + spec.target.t_vec


def scene_objects(spec: SceneSpec, hulls: Mapping[int, np.ndarray]) -> list[np.ndarray]:
    """`spec`'s objects in its camera frame: the target and each labelled object beside it, given by
    `hulls` (the vertices of each model's convex hull, model frame, by obj_id; the target's is OBJ_ID's),
    then each prop's mesh."""
    props = (np.asarray(prop_mesh(p).vertices) for p in spec.props)
    return [target_hull(spec, hulls), *object_hulls(spec, hulls), *props]


def scene_region(spec: SceneSpec, hulls: Mapping[int, np.ndarray], reach_px: float, margin_px: int) -> Region:
    """covered_region of `spec`'s camera (the one rendered) around its objects (scene_objects)."""
    cam = spec.camera
    return covered_region(cam.K_mat, cam.width, cam.height, scene_objects(spec, hulls), reach_px, margin_px)


def scene_regions(
    spec: SceneSpec, hulls: Mapping[int, np.ndarray], reach_px: float, margin_px: int
) -> tuple[Region, ...]:
    """covered_regions of `spec`'s camera around its objects (scene_objects)."""
    cam = spec.camera
    return covered_regions(cam.K_mat, cam.width, cam.height, scene_objects(spec, hulls), reach_px, margin_px)
