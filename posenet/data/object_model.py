"""The target object as posenet needs it: vertices, extent, diameter, symmetries, surface regions and points.

Read from a dataset's BOP model files (millimetres) and converted to metres. Regions (FPS on the vertices,
as GDR-Net) and the surface points (a fixed-seed, area-weighted sample of the faces) are deterministic, so
every process and every run of one dataset agrees.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import trimesh
from scipy.spatial import ConvexHull, QhullError

from posenet.data.layout import MAKE_ONE
from posenet.errors import PosenetError
from scgen.io import NOT_A_FOLDER, bop, not_a_dataset

SURFACE_POINTS_SEED = 0  # fixed: the PM loss and ADD / ADD-S see the same points in every run


@dataclass(frozen=True)
class ObjectModel:
    """One object in metres, in the dataset's model frame."""

    obj_id: int
    vertices: np.ndarray  # (V, 3)
    faces: np.ndarray  # (F, 3) triangles of the vertices: predict draws the silhouette from them
    extent: np.ndarray  # (3,) bbox size per axis: xyz maps are normalised as xyz / extent + 0.5
    diameter: float
    fps_points: np.ndarray  # (num_regions, 3) surface-region centres, FPS on the vertices
    pm_points: np.ndarray  # (num_pm, 3) uniform surface points: the PM loss and ADD / ADD-S use them
    # (K, 4, 4) transforms S with X_cam = R·(S·X) + t showing the same view, identity first (models_info's
    # symmetries, continuous ones discretised: bop.symmetry_transforms); K = 1 without symmetries
    symmetries: np.ndarray
    # the vertices of the convex hull of `vertices`: through a pinhole, the box of the projected model is
    # the box of these (posenet.predict.recrop.model_box), ~100 of the bundled model's 5,834
    hull: np.ndarray

    @property
    def symmetric(self) -> bool:
        """Whether models_info declares any symmetry (BOP's symmetric objects)."""
        return len(self.symmetries) > 1

    def to_record(self) -> dict[str, Any]:
        """What a checkpoint keeps of the object (tensors, as torch's safe loader reads them), so a pose
        can be predicted, scored and drawn without the dataset: object_from_record rebuilds the rest."""
        return {
            "obj_id": self.obj_id,
            "vertices": torch.from_numpy(self.vertices.astype(np.float64)),
            "faces": torch.from_numpy(self.faces.astype(np.int64)),
            "extent": self.extent.tolist(),
            "diameter": self.diameter,
            "symmetries": torch.from_numpy(self.symmetries.astype(np.float64)),
        }


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
    models = root / bop.MODELS_DIR
    info_path, ply_path = models / bop.MODELS_INFO_FILE, models / bop.model_file(obj_id)
    for path in (info_path, ply_path):
        if not path.is_file():
            why = NOT_A_FOLDER if not root.is_dir() else f"has no {path.relative_to(root)} {MAKE_ONE}"
            raise PosenetError(not_a_dataset(root, why))
    try:
        info = bop.read_models_info(root)[str(obj_id)]
        extent = bop.model_size_m(info)
        symmetries = bop.symmetry_transforms(info)
    except (KeyError, TypeError, ValueError) as exc:
        raise PosenetError(f"{info_path}: no valid entry for object {obj_id}") from exc
    mesh = bop.read_model_mesh(root, obj_id)
    if len(mesh.vertices) == 0 or len(mesh.faces) == 0 or mesh.area <= 0:
        raise PosenetError(f"{ply_path} has no surface (vertices and faces of non-zero area)")
    diameter = float(info["diameter"]) / bop.MM_PER_M
    return _object_model(obj_id, mesh, extent, diameter, symmetries, num_regions, num_pm)


def object_from_record(record: dict[str, Any], num_regions: int, num_pm: int) -> ObjectModel:
    """The ObjectModel of ObjectModel.to_record's dict: the same regions and surface points as the
    dataset's model gave (both are drawn from the mesh with fixed seeds)."""
    mesh = trimesh.Trimesh(
        np.asarray(record["vertices"], np.float64), np.asarray(record["faces"], np.int64), process=False
    )
    extent = np.asarray(record["extent"], np.float64)
    symmetries = np.asarray(record["symmetries"], np.float64)
    return _object_model(
        int(record["obj_id"]), mesh, extent, float(record["diameter"]), symmetries, num_regions, num_pm
    )


def _object_model(
    obj_id: int,
    mesh: trimesh.Trimesh,
    extent: np.ndarray,
    diameter: float,
    symmetries: np.ndarray,
    num_regions: int,
    num_pm: int,
) -> ObjectModel:
    vertices = np.asarray(mesh.vertices)
    return ObjectModel(
        obj_id=obj_id,
        vertices=vertices,
        faces=np.asarray(mesh.faces),
        extent=extent,
        diameter=diameter,
        fps_points=farthest_point_sampling(vertices, num_regions),
        pm_points=surface_points(mesh, num_pm),
        symmetries=symmetries,
        hull=hull_vertices(vertices),
    )


def hull_vertices(vertices: np.ndarray) -> np.ndarray:
    """The vertices on the convex hull of a point set (all of them where qhull cannot build one: a flat
    or degenerate set)."""
    try:
        return np.asarray(vertices)[ConvexHull(vertices).vertices]
    except QhullError:
        return np.asarray(vertices)
