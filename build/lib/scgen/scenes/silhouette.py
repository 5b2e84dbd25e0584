"""Silhouettes of convex pieces on small pixel grids: the sampler's cheap stand-in for a render.

A convex piece projects (perspective or orthographic) to the convex hull of its projected vertices,
so a union of filled hulls gives an object's silhouette in microseconds per piece. The sampler uses
it to aim occluders at an occlusion ratio (camera view) and shadow casters at a shadowed share of
the target (sun view); the labels themselves are always measured on the real render.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import trimesh

SUBPIXEL_BITS = 4  # cv2 fixed-point vertices: 1/16 pixel
FINE = 4  # fill at 4x the grid resolution, sample at the pixel centres
NEAR_Z = 1e-3  # metres; points closer to the camera plane cannot be projected


@dataclass(frozen=True)
class TargetShape:
    """The target as convex pieces (hull vertices, model frame, metres): one per connected component.

    Components that are not convex are over-approximated by their hull; for CAD made of primitive
    parts (the bundled spacecraft) it matches the rendered mask with IoU above 0.95 at 320x240.
    """

    pieces: tuple[np.ndarray, ...]
    radius: float  # largest distance of a vertex from the model origin
    diameter: float  # the model's diameter (largest vertex distance), as in models_info

    @staticmethod
    def from_mesh(mesh: trimesh.Trimesh, diameter: float) -> TargetShape:
        """The shape of a target mesh (TargetModel.mesh) with its diameter (TargetModel.diameter)."""
        pieces = []
        for comp in mesh.split(only_watertight=False):
            v = np.unique(np.asarray(comp.vertices, np.float64), axis=0)
            if len(v) > 8:
                v = np.asarray(trimesh.convex.convex_hull(v).vertices)
            pieces.append(v)
        radius = float(max(np.linalg.norm(p, axis=1).max() for p in pieces))
        return TargetShape(tuple(pieces), radius, float(diameter))

    def in_camera(self, R: np.ndarray, t: np.ndarray) -> list[np.ndarray]:
        return [p @ R.T + t for p in self.pieces]


@dataclass(frozen=True)
class Grid:
    """An affine pixel grid: grid coordinate = scale * (p - origin) for 2D points p."""

    origin: tuple[float, float]
    scale: float
    height: int
    width: int

    def fill(self, pieces_2d: list[np.ndarray]) -> np.ndarray:
        """Union of the filled convex hulls of the 2D point sets (bool mask, height x width).

        Filled on a grid FINE times denser and read back at the pixel centres: cv2 fills every
        pixel a polygon touches, which would otherwise widen thin parts by about a pixel.
        """
        fine = np.zeros(((self.height - 1) * FINE + 1, (self.width - 1) * FINE + 1), np.uint8)
        o = np.asarray(self.origin)
        for pts in pieces_2d:
            g = np.round((pts - o) * self.scale * FINE * (1 << SUBPIXEL_BITS))
            g = np.clip(g, -(2**26), 2**26).astype(np.int32)  # far-off points stay representable
            cv2.fillConvexPoly(fine, cv2.convexHull(g), 1, lineType=cv2.LINE_8, shift=SUBPIXEL_BITS)
        return fine[::FINE, ::FINE].astype(bool)

    def covered(self, mask: np.ndarray, pieces_2d: list[np.ndarray]) -> int:
        """Pixels of `mask` (on this grid) inside the union of hulls: filled only over their bounding box."""
        pts = (np.concatenate(pieces_2d) - np.asarray(self.origin)) * self.scale
        lo = np.maximum(np.ceil(pts.min(axis=0)), 0).astype(int)
        hi = np.minimum(np.floor(pts.max(axis=0)), [self.width - 1, self.height - 1]).astype(int)
        if np.any(hi < lo):
            return 0
        sub = Grid(tuple(np.asarray(self.origin) + lo / self.scale), self.scale, *(hi - lo + 1)[::-1])
        return int((mask[lo[1] : hi[1] + 1, lo[0] : hi[0] + 1] & sub.fill(pieces_2d)).sum())


@dataclass(frozen=True)
class CameraView:
    """The target's silhouette in a window of the image (downscaled for big targets)."""

    K: np.ndarray
    grid: Grid
    mask: np.ndarray  # target silhouette on the grid, inside the image only
    centroid_px: np.ndarray  # image coordinates of the silhouette's centroid
    extent_px: float  # largest image distance of a silhouette pixel from the centroid

    def overlap(self, pieces_cam: list[np.ndarray]) -> float:
        """Share of the target silhouette the pieces cover in the image.

        Pieces wholly behind the camera are invisible (0.0); pieces straddling the camera plane
        cannot be projected and count as covering everything (1.0).
        """
        z = np.concatenate([p[:, 2] for p in pieces_cam])
        if z.max() <= 0.0:
            return 0.0
        if z.min() <= NEAR_Z:
            return 1.0
        proj = [(p @ self.K.T)[:, :2] / p[:, 2:3] for p in pieces_cam]
        return self.grid.covered(self.mask, proj) / float(self.mask.sum())


def camera_view(
    K: np.ndarray, width: int, height: int, target_cam: list[np.ndarray], max_side: int = 128
) -> CameraView | None:
    """The target's silhouette on a grid of at most `max_side` pixels a side; None if it misses the image."""
    proj = [(p @ K.T)[:, :2] / (p @ K.T)[:, 2:3] for p in target_cam]
    pts = np.concatenate(proj)
    lo = np.maximum(np.floor(pts.min(axis=0)), 0.0)
    hi = np.minimum(np.ceil(pts.max(axis=0)), [width - 1, height - 1])
    if np.any(hi < lo):
        return None
    scale = min(1.0, max_side / float(max(hi - lo) + 1))
    size = np.floor((hi - lo) * scale).astype(int) + 1
    grid = Grid((float(lo[0]), float(lo[1])), scale, int(size[1]), int(size[0]))
    mask = grid.fill(proj)
    if not mask.any():
        return None
    ys, xs = np.nonzero(mask)
    pix = np.stack([xs, ys], 1) / scale + lo
    centroid = pix.mean(axis=0)
    extent = float(np.linalg.norm(pix - centroid, axis=1).max()) + 1.0 / scale
    return CameraView(K, grid, mask, centroid, extent)


@dataclass(frozen=True)
class SunView:
    """The target seen from the sun (orthographic along the sun direction), on a square grid."""

    basis: np.ndarray  # 2 x 3: unit axes of the view plane, both orthogonal to the sun direction
    grid: Grid
    mask: np.ndarray

    def coverage(self, pieces_cam: list[np.ndarray]) -> float:
        """Share of the target's sun-view silhouette the pieces cover (their sunward side is not checked)."""
        return self.grid.covered(self.mask, [p @ self.basis.T for p in pieces_cam]) / float(self.mask.sum())


def sun_view(
    basis: np.ndarray, centre: np.ndarray, radius: float, target_cam: list[np.ndarray], side: int = 64
) -> SunView:
    """Orthographic view of the ball (centre, radius) holding the target, looking along the sun."""
    c2 = basis @ centre
    grid = Grid((float(c2[0] - radius), float(c2[1] - radius)), (side - 1) / (2.0 * radius), side, side)
    return SunView(basis, grid, grid.fill([p @ basis.T for p in target_cam]))
