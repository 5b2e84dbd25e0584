"""Place occluders and shadow casters so that a requested occlusion ratio or shadowed share is hit.

Both searches slide a prop sideways from full overlap to none and bisect on the measured overlap of
silhouettes (scgen.scenes.silhouette): the camera view for occlusion, the sun view for shadows.
Pure and deterministic: every random number comes from the factor stream passed in.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from scgen.scenes.geometry import backproject, focal_length, look_rotation, random_rotation
from scgen.scenes.props import bounding_radius, local_pieces, unit_extents
from scgen.scenes.silhouette import CameraView, SunView
from scgen.scenes.spec import Pose, PropSpec

BISECTION_STEPS = 12
GROWTH = 1.3  # size factor per step when a prop is too small to reach the goal even fully overlapping
MAX_GROWTH_STEPS = 8


@dataclass(frozen=True)
class Blank:
    """A prop before placement: shape, proportions, orientation and material, at half-length 1."""

    role: str
    shape: str
    unit: np.ndarray
    R: np.ndarray
    material: str
    seed: int

    @staticmethod
    def draw(
        rng: np.random.Generator, role: str, shapes: tuple[str, ...], materials: tuple[str, ...],
        facing: np.ndarray | None = None,
    ) -> Blank:  # fmt: skip
        """Random shape and material; panels face `facing` when given (a caster's plate faces the sun)."""
        shape = shapes[int(rng.integers(len(shapes)))]
        unit = unit_extents(shape, rng)
        R = look_rotation(facing, rng) if facing is not None and shape == "panel" else random_rotation(rng)
        material = materials[int(rng.integers(len(materials)))]
        return Blank(role, shape, unit, R, material, int(rng.integers(2**31)))

    @property
    def bound(self) -> float:
        """Bounding radius at half-length 1."""
        return bounding_radius(self.shape, self.unit)

    def unit_pieces(self) -> list[np.ndarray]:
        """Piece vertices at half-length 1, rotated into the camera frame (geometry scales linearly)."""
        return [v @ self.R.T for v, _ in local_pieces(self.shape, self.unit, self.seed)]

    def spec(self, half: float, centre: np.ndarray) -> PropSpec:
        size = tuple(float(x) for x in self.unit * half)
        pose = Pose.from_arrays(self.R, centre)
        return PropSpec(self.role, self.shape, size, pose, self.material, self.seed)


def bisect_offset(overlap: Callable[[float], float], goal: float, hi: float) -> float:
    """An offset in [0, hi] whose overlap is just above `goal`, given overlap(0) >= goal > overlap(hi)."""
    lo = 0.0
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        if overlap(mid) >= goal:
            lo = mid
        else:
            hi = mid
    return lo


def place_occluder(
    rng: np.random.Generator, cfg: dict[str, Any], view: CameraView, t: np.ndarray, radius: float,
    group: str, blank: Blank,
) -> PropSpec:  # fmt: skip
    """An occluder in front of the target whose silhouette covers about the requested share of it.

    'none' places a distractor beside the target (no overlap). The occluder's projected size is
    `size_rel` target radii; it grows when even a centred placement stays below the goal.
    """
    K = view.K
    f = focal_length(K)
    rel = rng.uniform(*cfg["size_rel"])
    frac = rng.uniform(*cfg["depth_frac"])
    phi = rng.uniform(0.0, 2 * np.pi)
    direction = np.array([np.cos(phi), np.sin(phi)])
    goal = rng.uniform(*cfg["target_r_occ"][group]) if group != "none" else 0.0
    pieces = blank.unit_pieces()
    z_front = t[2] - radius  # the occluder's far side stays in front of the target's bounding ball

    def place(rel: float, offset: float) -> tuple[float, np.ndarray]:
        depth = frac * z_front / (1.0 + blank.bound * rel * radius / t[2])
        half = rel * radius * depth / t[2]
        u, v = view.centroid_px + offset * direction
        return half, backproject(K, u, v, depth)

    def overlap(rel: float, offset: float) -> float:
        half, centre = place(rel, offset)
        return view.overlap([half * p + centre for p in pieces])

    clear = view.extent_px + 1.2 * f * blank.bound * rel * radius / t[2] + 2.0  # offset with no overlap
    if group == "none":
        offset = clear * rng.uniform(1.0, 1.6)
        while overlap(rel, offset) > 0.0:
            offset *= GROWTH
    else:
        largest = 0.8 * t[2] / (blank.bound * radius)  # beyond this its near side nears the camera plane
        for _ in range(MAX_GROWTH_STEPS):
            if overlap(rel, 0.0) >= goal or rel * GROWTH > largest:
                break
            rel *= GROWTH
        clear = view.extent_px + 1.2 * f * blank.bound * rel * radius / t[2] + 2.0
        offset = bisect_offset(lambda o: overlap(rel, o), goal, clear) if overlap(rel, 0.0) >= goal else 0.0
    half, centre = place(rel, offset)
    return blank.spec(half, centre)


def place_caster(
    rng: np.random.Generator, cfg: dict[str, Any], view: CameraView, sun: SunView, t: np.ndarray,
    sun_dir: np.ndarray, radius: float, diameter: float, blank: Blank,
) -> PropSpec | None:  # fmt: skip
    """A prop on the sun side of the target shading about `coverage` of its sun-view silhouette
    (or, with `offset_diam` set, offset that far from the sun line through the target centre).

    The sun-view overlap does not depend on how far along the sun direction the caster sits, so
    after aiming it sideways it is pushed sunwards until the camera no longer sees it in front of
    the target (possibly behind the camera: the chaser's own shadow). None if that never happens.
    """
    half = 0.5 * rng.uniform(*cfg["size_diam"]) * diameter
    goal = rng.uniform(*cfg["coverage"])
    phi = rng.uniform(0.0, 2 * np.pi)
    lateral = np.cos(phi) * sun.basis[0] + np.sin(phi) * sun.basis[1]
    along = rng.uniform(*cfg["distance_diam"]) * diameter
    pieces = blank.unit_pieces()

    def at(half: float, offset: float, distance: float) -> list[np.ndarray]:
        centre = t + sun_dir * distance + lateral * offset
        return [half * p + centre for p in pieces]

    if cfg["offset_diam"] is not None:  # explicit geometry instead of an aimed coverage
        offset = rng.uniform(*cfg["offset_diam"]) * diameter
    else:
        for _ in range(MAX_GROWTH_STEPS):
            if sun.coverage(at(half, 0.0, 0.0)) >= goal:
                break
            half *= GROWTH
        offset = bisect_offset(lambda o: sun.coverage(at(half, o, 0.0)), goal, radius + blank.bound * half)
    distance = radius + blank.bound * half + along
    for _ in range(24):
        if view.overlap(at(half, offset, distance)) == 0.0:
            return blank.spec(half, t + sun_dir * distance + lateral * offset)
        distance *= 1.5
    return None
