"""The BOP format (docs/dataset.md): file names, millimetres on disk, and the entries of its JSON files.

One home for what scgen's writer produces and what validate, stats, posenet and its viewers read,
so the two sides cannot drift apart. Poses and sizes are metres in memory and millimetres on disk.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from scgen.errors import ScgenError

MM_PER_M = 1000.0
CAMERA_FILE = "camera.json"
MODELS_DIR = "models"
MODELS_INFO_FILE = "models_info.json"
SCENE_FILES = ("scene_gt", "scene_camera", "scene_gt_info")  # {name}.json in every scene folder
MASK_DIRS = {False: "mask", True: "mask_visib"}


def model_file(obj_id: int) -> str:
    return f"obj_{obj_id:06d}.ply"


def scene_dir(root: Path, split: str, scene_id: int) -> Path:
    return Path(root) / split / f"{scene_id:06d}"


def scene_file(scene: Path, name: str) -> Path:
    """One of a scene folder's SCENE_FILES."""
    return scene / f"{name}.json"


def rgb_path(scene: Path, im_id: int, ext: str = "png") -> Path:
    return scene / "rgb" / f"{im_id:06d}.{ext}"


def mask_path(scene: Path, im_id: int, inst: int, visib: bool = False) -> Path:
    return scene / MASK_DIRS[visib] / f"{im_id:06d}_{inst:06d}.png"


def xyz_path(scene: Path, im_id: int, inst: int) -> Path:
    """Our addition to BOP: the instance's model-coordinate map, cropped to its xyz_box."""
    return scene / "xyz" / f"{im_id:06d}_{inst:06d}.exr"


def depth_path(scene: Path, im_id: int) -> Path:
    return scene / "depth" / f"{im_id:06d}.png"


def gt_entry(R: np.ndarray, t_m: np.ndarray, obj_id: int) -> dict[str, Any]:
    """A scene_gt.json instance: model-to-camera rotation (row-major) and translation in millimetres."""
    return {"cam_R_m2c": [float(x) for x in np.asarray(R).reshape(9)],
            "cam_t_m2c": [float(x) for x in np.asarray(t_m) * MM_PER_M], "obj_id": obj_id}  # fmt: skip


def gt_pose(entry: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """(R, t in metres) of a scene_gt.json instance."""
    R = np.asarray(entry["cam_R_m2c"], dtype=np.float64).reshape(3, 3)
    return R, np.asarray(entry["cam_t_m2c"], dtype=np.float64) / MM_PER_M


def camera_K(entry: dict[str, Any]) -> np.ndarray:
    """The 3 x 3 intrinsics of a scene_camera.json entry."""
    return np.asarray(entry["cam_K"], dtype=np.float64).reshape(3, 3)


def models_info_entry(bounds_m: np.ndarray, diameter_m: float) -> dict[str, float]:
    """A models_info.json entry (millimetres) from the model's bounds (2 x 3, metres) and diameter."""
    lo, hi = np.asarray(bounds_m) * MM_PER_M
    size = hi - lo
    return {"diameter": float(diameter_m * MM_PER_M), "min_x": float(lo[0]), "min_y": float(lo[1]),
            "min_z": float(lo[2]), "size_x": float(size[0]), "size_y": float(size[1]),
            "size_z": float(size[2])}  # fmt: skip


def model_size_m(info: dict[str, Any]) -> np.ndarray:
    """The size (x, y, z) of a models_info entry's bounding box, in metres."""
    return np.array([info["size_x"], info["size_y"], info["size_z"]], dtype=np.float64) / MM_PER_M


def model_box_m(info: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """(min corner, size) of a models_info entry's bounding box, in metres."""
    lo = np.array([info["min_x"], info["min_y"], info["min_z"]], dtype=np.float64) / MM_PER_M
    return lo, model_size_m(info)


def read_json(path: Path) -> Any:
    """A JSON file of the dataset, or a one-line ScgenError naming it."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ScgenError(f"cannot read {path}: {exc}") from exc


def read_models_info(root: Path) -> dict[str, Any]:
    return read_json(Path(root) / MODELS_DIR / MODELS_INFO_FILE)


def read_model_mesh(root: Path, obj_id: int) -> trimesh.Trimesh:
    """The object's PLY model, in metres."""
    path = Path(root) / MODELS_DIR / model_file(obj_id)
    try:
        mesh = trimesh.load(str(path), force="mesh", process=False)
    except (OSError, ValueError) as exc:
        raise ScgenError(f"cannot read model {path}: {exc}") from exc
    mesh.vertices = np.asarray(mesh.vertices, dtype=np.float64) / MM_PER_M
    return mesh
