"""Procedural geometry of non-target objects, as convex pieces in the prop's local frame.

The sampler uses the pieces' vertices to predict occlusion and cast shadows (a convex piece projects
to the convex hull of its projected vertices); every renderer meshes the very same pieces, so the
prediction and the rendered labels see one geometry.
"""

from __future__ import annotations

import functools

import numpy as np
import trimesh

from scgen.scenes.geometry import orthonormal_basis


def unit_extents(shape: str, rng: np.random.Generator) -> np.ndarray:
    """Local box extents of a prop of half-length 1 (its longest side is 2), with random proportions."""
    if shape == "panel":
        return np.array([2.0, 2.0 * rng.uniform(0.4, 1.0), 0.04])
    if shape == "box":
        return np.array([2.0, 2.0 * rng.uniform(0.5, 1.0), 2.0 * rng.uniform(0.5, 1.0)])
    if shape == "debris":
        return np.array([2.0, 2.0 * rng.uniform(0.3, 0.8), 2.0 * rng.uniform(0.2, 0.6)])
    return {"rod": np.array([2.0, 0.12, 0.12]), "arm": np.array([2.0, 0.25, 0.25]),
            "truss": np.array([2.0, 0.6, 0.6])}[shape]  # fmt: skip


Piece = tuple[np.ndarray, np.ndarray]  # a convex piece: vertices (N x 3, metres), triangles (M x 3)


def local_pieces(shape: str, size: np.ndarray, seed: int) -> list[Piece]:
    """Convex pieces making up a prop of `shape` with local box extents `size` (metres)."""
    size = np.asarray(size, dtype=np.float64)
    if shape in ("panel", "box"):
        return [_box(size)]
    if shape in ("rod", "arm"):
        x0 = 0.5 * size[0]
        rod = _cylinder(0.5 * min(size[1], size[2]), [-x0, 0, 0], [x0, 0, 0], 20)
        if shape == "rod":
            return [rod]
        r, h = 0.9 * size[1], 0.6 * size[1]  # a robotic-arm link: a joint housing at each end
        return [rod] + [_cylinder(r, [end, 0, -h], [end, 0, h], 20) for end in (-x0, x0)]
    if shape == "debris":  # an irregular fragment: the hull of jittered points
        hull = trimesh.convex.convex_hull(np.random.default_rng(seed).uniform(-0.5, 0.5, size=(24, 3)) * size)
        return [(np.asarray(hull.vertices), np.asarray(hull.faces))]
    if shape == "truss":  # a square truss segment: four longerons and crossed diagonals
        h, r, x0 = 0.5 * size[1], 0.04 * size[1], 0.5 * size[0]
        members = [[[-x0, y, z], [x0, y, z]] for y, z in ((-h, -h), (-h, h), (h, -h), (h, h))]
        for x in np.linspace(-x0, x0, 4):
            members += [[[x, -h, -h], [x, h, h]], [[x, -h, h], [x, h, -h]]]
        return [_cylinder(r, p0, p1, 8) for p0, p1 in members]
    raise ValueError(f"unknown prop shape {shape!r}")


def _box(size: np.ndarray) -> Piece:
    box = _unit_box()
    return box[0] * size, box[1]


def _cylinder(radius: float, p0: list[float], p1: list[float], sections: int) -> Piece:
    """A closed cylinder of `radius` from p0 to p1."""
    p0, p1 = np.asarray(p0, np.float64), np.asarray(p1, np.float64)
    axis = p1 - p0
    length = float(np.linalg.norm(axis))
    u, w = orthonormal_basis(axis / length)
    frame = np.stack([u, w, axis / length], axis=1)
    v, f = _unit_cylinder(sections)
    return (v * [radius, radius, length]) @ frame.T + 0.5 * (p0 + p1), f


@functools.cache
def _unit_box() -> Piece:
    m = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    return np.asarray(m.vertices), np.asarray(m.faces)


@functools.cache
def _unit_cylinder(sections: int) -> Piece:
    """Radius 1, height 1 along z, centred at the origin."""
    m = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=sections)
    return np.asarray(m.vertices), np.asarray(m.faces)


def bounding_radius(shape: str, size: np.ndarray) -> float:
    """Radius of a ball about the local origin holding the prop (half its box diagonal, joints included)."""
    size = np.asarray(size, dtype=np.float64)
    if shape == "arm":
        size = np.array([size[0] + 1.8 * size[1], 1.8 * size[1], 1.8 * size[1]])
    return float(0.5 * np.linalg.norm(size))
