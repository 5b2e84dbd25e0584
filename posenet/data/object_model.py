"""The target object as posenet needs it: vertices, extent, diameter, surface regions and surface points.

Read from a dataset's BOP model files (millimetres) and converted to metres. Regions (FPS on the vertices,
as GDR-Net) and the surface points (a fixed-seed, area-weighted sample of the faces) are deterministic, so
every process and every run of one dataset agrees.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from posenet.errors import PosenetError

SURFACE_POINTS_SEED = 0  # fixed: the PM loss and ADD / ADD-S see the same points in every run


@dataclass(frozen=True)
class ObjectModel:
    """One object in metres, in the dataset's model frame."""

    obj_id: int
    vertices: np.ndarray  # (V, 3)
    extent: np.ndarray  # (3,) bbox size per axis: xyz maps are normalised as xyz / extent + 0.5
    diameter: float
    fps_points: np.ndarray  # (num_regions, 3) surface-region centres, FPS on the vertices
    pm_points: np.ndarray  # (num_pm, 3) uniform surface points: the PM loss and ADD / ADD-S use them


def farthest_point_sampling(points: np.ndarray, n: int) -> np.ndarray:
    """n points by farthest-point sampling, starting from the point farthest from the centroid."""
    points = np.asarray(points, dtype=np.float64)
    chosen = [int(np.argmax(np.linalg.norm(points - points.mean(0), axis=1)))]
    dist = np.linalg.norm(points - points[chosen[0]], axis=1)
    for _ in range(1, min(n, len(points))):
        chosen.append(int(np.argmax(dist)))
        dist = np.minimum(dist, np.linalg.norm(points - points[chosen[-1]], axis=1))
    return points[chosen]


def surface_points(mesh: trimesh.Trimesh, n: int, seed: int = SURFACE_POINTS_SEED) -> np.ndarray:
    """n points uniform over the surface area (faces picked by area, then uniform in the face), seeded.

    Unlike the CAD vertices, they do not over-weight densely meshed parts in ADD or the PM loss.
    """
    points, _ = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return np.asarray(points, dtype=np.float64)


def load_object_model(root: Path, obj_id: int, num_regions: int, num_pm: int) -> ObjectModel:
    """Object `obj_id` of the dataset at `root`: models/models_info.json and models/obj_{id:06d}.ply."""
    info_path = root / "models" / "models_info.json"
    ply_path = root / "models" / f"obj_{obj_id:06d}.ply"
    if not info_path.is_file():
        raise PosenetError(f"{root} is not a dataset: {info_path.relative_to(root)} is missing")
    try:
        info = json.loads(info_path.read_text())[str(obj_id)]
    except (json.JSONDecodeError, KeyError) as exc:
        raise PosenetError(f"{info_path}: no valid entry for object {obj_id}") from exc
    if not ply_path.is_file():
        raise PosenetError(f"{root} is not a dataset: {ply_path.relative_to(root)} is missing")
    mesh = trimesh.load(str(ply_path), force="mesh", process=False)
    vertices = np.asarray(mesh.vertices, dtype=np.float64) / 1000.0
    if len(vertices) == 0 or len(mesh.faces) == 0 or mesh.area <= 0:
        raise PosenetError(f"{ply_path} has no surface (vertices and faces of non-zero area)")
    extent = np.array([info["size_x"], info["size_y"], info["size_z"]], dtype=np.float64) / 1000.0
    return ObjectModel(
        obj_id=obj_id,
        vertices=vertices,
        extent=extent,
        diameter=float(info["diameter"]) / 1000.0,
        fps_points=farthest_point_sampling(vertices, num_regions),
        pm_points=surface_points(mesh, num_pm) / 1000.0,
    )
