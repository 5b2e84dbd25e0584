"""Index of a BOP-layout dataset directory (docs/dataset.md): one `Instance` per annotated target.

Only metadata is read here (JSON files); pixels are read lazily by the Dataset.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from posenet.errors import PosenetError


@dataclass(frozen=True)
class Instance:
    """One annotated object instance in one image. Poses in metres, boxes [x, y, w, h] in pixels."""

    split: str
    obj_id: int
    scene_id: int
    im_id: int
    inst: int
    rgb: Path
    mask: Path
    mask_visib: Path
    xyz: Path
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    bbox_obj: tuple[int, int, int, int]
    bbox_visib: tuple[int, int, int, int]
    xyz_box: tuple[int, int, int, int]
    visib_fract: float
    px_count_visib: int
    image_size: tuple[int, int]  # (width, height)

    @property
    def key(self) -> tuple[int, int]:
        """(scene_id, im_id): the image this instance belongs to; boxes and predictions are keyed by it."""
        return self.scene_id, self.im_id


def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise PosenetError(f"cannot read {path}: {exc}") from exc


def image_size(root: Path) -> tuple[int, int]:
    """(width, height) from camera.json; also the check that `root` is a dataset at all."""
    cam_path = root / "camera.json"
    if not root.is_dir() or not cam_path.is_file():
        raise PosenetError(f"{root} is not a dataset folder (no camera.json)")
    cam = _read_json(cam_path)
    return int(cam["width"]), int(cam["height"])


def scan_split(root: Path, split: str, obj_id: int) -> list[Instance]:
    """Every instance of object `obj_id` in `root/split/*/`, sorted by (scene_id, im_id, inst)."""
    size = image_size(root)
    split_dir = root / split
    scenes = sorted(p for p in split_dir.glob("[0-9]*") if (p / "scene_gt.json").is_file())
    if not scenes:
        found = sorted(p.name for p in root.iterdir() if p.is_dir() and any(p.glob("*/scene_gt.json")))
        raise PosenetError(f"{root} has no split '{split}' (splits found: {', '.join(found) or 'none'})")
    out: list[Instance] = []
    for scene in scenes:
        out.extend(_scan_scene(scene, split, obj_id, size))
    return out


def _scan_scene(scene: Path, split: str, obj_id: int, size: tuple[int, int]) -> list[Instance]:
    gt, cams, infos = (
        _read_json(scene / f) for f in ("scene_gt.json", "scene_camera.json", "scene_gt_info.json")
    )
    out: list[Instance] = []
    try:
        for im_key in sorted(gt, key=int):
            im_id = int(im_key)
            rgb = next(
                (p for p in (scene / "rgb" / f"{im_id:06d}{e}" for e in (".png", ".jpg")) if p.is_file()),
                None,
            )
            if rgb is None:
                continue  # a sample still being written: nothing to train or test on yet
            K = np.asarray(cams[im_key]["cam_K"], dtype=np.float64).reshape(3, 3)
            for inst, (ann, info) in enumerate(zip(gt[im_key], infos[im_key], strict=True)):
                if int(ann["obj_id"]) == obj_id:
                    out.append(_instance(scene, split, im_id, inst, rgb, K, ann, info, size))
    except (KeyError, ValueError, TypeError) as exc:
        raise PosenetError(f"{scene}: malformed BOP annotation ({type(exc).__name__}: {exc})") from exc
    return out


def _instance(
    scene: Path,
    split: str,
    im_id: int,
    inst: int,
    rgb: Path,
    K: np.ndarray,
    ann: dict,
    info: dict,
    size: tuple,
) -> Instance:
    name = f"{im_id:06d}_{inst:06d}"
    return Instance(
        split=split,
        obj_id=int(ann["obj_id"]),
        scene_id=int(scene.name),
        im_id=im_id,
        inst=inst,
        rgb=rgb,
        mask=scene / "mask" / f"{name}.png",
        mask_visib=scene / "mask_visib" / f"{name}.png",
        xyz=scene / "xyz" / f"{name}.exr",
        K=K,
        R=np.asarray(ann["cam_R_m2c"], dtype=np.float64).reshape(3, 3),
        t=np.asarray(ann["cam_t_m2c"], dtype=np.float64) / 1000.0,
        bbox_obj=tuple(int(v) for v in info["bbox_obj"]),
        bbox_visib=tuple(int(v) for v in info["bbox_visib"]),
        xyz_box=tuple(int(v) for v in info.get("xyz_box", info["bbox_visib"])),
        visib_fract=float(info["visib_fract"]),
        px_count_visib=int(info["px_count_visib"]),
        image_size=size,
    )
