"""Any BOP dataset as `scgen annotate` and `scgen validate` read it: image size, images, ground truth, models.

Everything is checked up front and the first problem is named (ScgenError), so bad input writes nothing.
No renderer here: validate reads datasets through this module too.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from scgen.errors import ScgenError
from scgen.io import bop
from scgen.scenes.spec import CameraSpec


@dataclass(frozen=True)
class BopImage:
    """One image: where it is, its scene_gt.json instances in file order (obj_id, R, t in metres), its K."""

    split: str
    scene_id: int
    im_id: int
    instances: tuple[tuple[int, np.ndarray, np.ndarray], ...]
    K: tuple[float, ...]  # 9 numbers, row-major


@dataclass(frozen=True)
class BopDataset:
    root: Path
    size: tuple[int, int]  # (width, height) from camera.json
    images: tuple[BopImage, ...]  # sorted by split, scene, im_id
    models_info: dict[str, Any]

    def scene(self, image: BopImage) -> Path:
        return bop.scene_dir(self.root, image.split, image.scene_id)

    def camera(self, image: BopImage) -> CameraSpec:
        return CameraSpec(self.size[0], self.size[1], image.K, 0.0)

    @property
    def obj_ids(self) -> list[int]:
        return sorted({obj_id for im in self.images for obj_id, _, _ in im.instances})


def is_bop_dataset(root: Path) -> bool:
    """A folder with camera.json, models/models_info.json and at least one split of scene folders."""
    root = Path(root)
    return (
        (root / bop.CAMERA_FILE).is_file()
        and (root / bop.MODELS_DIR / bop.MODELS_INFO_FILE).is_file()
        and bool(bop.split_names(root))
    )


def open_bop_dataset(root: Path, split: str | None = None) -> BopDataset:
    """Every image of `split` (default: every split) with its ground truth; checks that the models exist."""
    root = Path(root)
    if not root.is_dir() or not is_bop_dataset(root):
        raise ScgenError(
            f"not a BOP dataset: {root} needs {bop.CAMERA_FILE}, {bop.MODELS_DIR}/{bop.MODELS_INFO_FILE} "
            "and split folders of scene folders with scene_gt.json"
        )
    splits = bop.split_names(root)
    if split is not None and split not in splits:
        raise ScgenError(f"unknown split '{split}' in {root} (splits: {', '.join(splits)})")
    camera = bop.read_json(root / bop.CAMERA_FILE)
    try:
        size = (int(camera["width"]), int(camera["height"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise ScgenError(f"{root / bop.CAMERA_FILE} has no image width and height ({exc})") from exc
    images = tuple(
        image for s in ([split] if split else splits) for scene in bop.scene_dirs(root, s)
        for image in read_scene(scene, s)
    )  # fmt: skip
    data = BopDataset(root, size, images, bop.read_models_info(root))
    check_models(data)
    return data


def read_scene(scene: Path, split: str) -> list[BopImage]:
    """The images of one scene folder, from its scene_gt.json and scene_camera.json."""
    gt, cams = (bop.read_json(bop.scene_file(scene, name)) for name in ("scene_gt", "scene_camera"))
    images = []
    try:
        for key in sorted(gt, key=int):
            if key not in cams:
                raise ScgenError(f"{scene}: image {key} is in scene_gt.json but not in scene_camera.json")
            instances = tuple((int(e["obj_id"]), *bop.gt_pose(e)) for e in gt[key])
            K = tuple(float(x) for x in bop.camera_K(cams[key]).reshape(9))
            images.append(BopImage(split, int(scene.name), int(key), instances, K))
    except (KeyError, TypeError, ValueError) as exc:
        raise ScgenError(f"{scene}: malformed scene_gt.json or scene_camera.json ({exc!r})") from exc
    return images


def check_models(data: BopDataset) -> None:
    """Every object of the ground truth has a model file and a models_info.json entry."""
    for obj_id in data.obj_ids:
        path = data.root / bop.MODELS_DIR / bop.model_file(obj_id)
        if not path.is_file():
            raise ScgenError(f"missing model of obj_id {obj_id}: {path}")
        if str(obj_id) not in data.models_info:
            raise ScgenError(f"obj_id {obj_id} has no entry in {bop.MODELS_DIR}/{bop.MODELS_INFO_FILE}")


def read_models(data: BopDataset) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """obj_id -> (vertices in metres, faces) of every object the ground truth uses."""
    out = {}
    for obj_id in data.obj_ids:
        mesh = bop.read_model_mesh(data.root, obj_id)
        if len(mesh.faces) == 0:
            raise ScgenError(f"model of obj_id {obj_id} has no faces")
        out[obj_id] = (np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64))
    return out
