"""The target object as posenet needs it: vertices, extent, diameter, surface regions and PM points.

Read from a dataset's BOP model files (millimetres) and converted to metres. Regions and PM points are
derived deterministically from the vertices, so every process and every run of one dataset agrees.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from posenet.errors import PosenetError

PM_POINTS_SEED = 0


@dataclass(frozen=True)
class ObjectModel:
    """One object in metres, in the dataset's model frame."""

    obj_id: int
    vertices: np.ndarray  # (V, 3)
    extent: np.ndarray  # (3,) bbox size per axis: xyz maps are normalised as xyz / extent + 0.5
    diameter: float
    fps_points: np.ndarray  # (num_regions, 3) surface-region centres
    pm_points: np.ndarray  # (<= num_pm, 3) points for the point-matching loss


def farthest_point_sampling(points: np.ndarray, n: int) -> np.ndarray:
    """n points by farthest-point sampling, starting from the point farthest from the centroid."""
    points = np.asarray(points, dtype=np.float64)
    chosen = [int(np.argmax(np.linalg.norm(points - points.mean(0), axis=1)))]
    dist = np.linalg.norm(points - points[chosen[0]], axis=1)
    for _ in range(1, min(n, len(points))):
        chosen.append(int(np.argmax(dist)))
        dist = np.minimum(dist, np.linalg.norm(points - points[chosen[-1]], axis=1))
    return points[chosen]


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
    if len(vertices) == 0:
        raise PosenetError(f"{ply_path} has no vertices")
    rng = np.random.default_rng(PM_POINTS_SEED)
    pm = vertices[rng.choice(len(vertices), size=min(num_pm, len(vertices)), replace=False)]
    extent = np.array([info["size_x"], info["size_y"], info["size_z"]], dtype=np.float64) / 1000.0
    return ObjectModel(
        obj_id=obj_id,
        vertices=vertices,
        extent=extent,
        diameter=float(info["diameter"]) / 1000.0,
        fps_points=farthest_point_sampling(vertices, num_regions),
        pm_points=pm,
    )
