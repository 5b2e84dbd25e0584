"""Index of a BOP-layout dataset directory (docs/dataset.md): one `Instance` per annotated target.

Only metadata is read here (JSON files); pixels are read lazily by the Dataset.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from posenet.errors import PosenetError
from scgen.io import NOT_A_FOLDER, bop, not_a_dataset

MAKE_ONE = "(make one with `scgen render`, or bring a BOP dataset with xyz maps: docs/dataset.md)"


@dataclass(frozen=True)
class Instance:
    """One annotated object instance in one image. Poses in metres; boxes [x, y, w, h] cover pixels
    x .. x + w - 1 (BOP's boxes, w = max - min, are converted on reading by bop.box_pixels); bbox_obj
    is the whole projection, so it may reach past the image."""

    split: str
    obj_id: int
    scene_id: int
    im_id: int
    inst: int  # index in the image's scene_gt list, whatever the objects: it names the mask and xyz files
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


def image_size(root: Path) -> tuple[int, int]:
    """(width, height) from camera.json; also the check that `root` is a dataset at all."""
    cam_path = root / bop.CAMERA_FILE
    if not root.is_dir():
        raise PosenetError(not_a_dataset(root, NOT_A_FOLDER))
    if not cam_path.is_file():
        raise PosenetError(not_a_dataset(root, f"has no {bop.CAMERA_FILE} {MAKE_ONE}"))
    cam = bop.read_json(cam_path)
    return int(cam["width"]), int(cam["height"])


def _has_gt(scene: Path) -> bool:
    return bop.scene_file(scene, "scene_gt").is_file()


def scan_split(root: Path, split: str, obj_id: int) -> list[Instance]:
    """Every instance of object `obj_id` in `root/split/*/`, sorted by (scene_id, im_id, inst); the
    instances of other objects in the same images are skipped, their files never opened."""
    size = image_size(root)
    split_dir = root / split
    scenes = sorted(p for p in split_dir.glob("[0-9]*") if _has_gt(p))
    if not scenes:
        found = sorted(
            p.name
            for p in root.iterdir()
            if p.is_dir() and any(p.glob("*/" + bop.scene_file(p, "scene_gt").name))
        )
        raise PosenetError(f"{root} has no split '{split}' (splits found: {', '.join(found) or 'none'})")
    out: list[Instance] = []
    for scene in scenes:
        out.extend(_scan_scene(scene, split, obj_id, size))
    return out


def _scan_scene(scene: Path, split: str, obj_id: int, size: tuple[int, int]) -> list[Instance]:
    gt, cams, infos = (bop.read_json(bop.scene_file(scene, name)) for name in bop.SCENE_FILES)
    out: list[Instance] = []
    try:
        for im_key in sorted(gt, key=int):
            im_id = int(im_key)
            rgb = next(
                (p for p in (bop.rgb_path(scene, im_id, e) for e in ("png", "jpg")) if p.is_file()), None
            )
            if rgb is None:
                continue  # a sample still being written: nothing to train or test on yet
            if any(cams[im_key].get("cam_dist", ())):
                raise PosenetError(
                    f"{scene}: image {im_id} was taken through a lens with distortion (cam_dist "
                    f"{cams[im_key]['cam_dist']}); posenet's crops and SITE assume a pinhole camera: render "
                    "with a pinhole camera (scgen render --camera default) or undistort the images first"
                )
            K = bop.camera_K(cams[im_key])
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
    R, t = bop.gt_pose(ann)
    return Instance(
        split=split,
        obj_id=int(ann["obj_id"]),
        scene_id=int(scene.name),
        im_id=im_id,
        inst=inst,
        rgb=rgb,
        mask=bop.mask_path(scene, im_id, inst),
        mask_visib=bop.mask_path(scene, im_id, inst, visib=True),
        xyz=bop.xyz_path(scene, im_id, inst),
        K=K,
        R=R,
        t=t,
        bbox_obj=bop.box_pixels(info["bbox_obj"]),
        bbox_visib=bop.box_pixels(info["bbox_visib"]),
        xyz_box=_xyz_box(info),
        visib_fract=float(info["visib_fract"]),
        px_count_visib=int(info["px_count_visib"]),
        image_size=size,
    )


def _xyz_box(info: dict) -> tuple[int, int, int, int]:
    """The pixels an instance's xyz crop covers: scgen's `xyz_box`, else (no xyz map: none in the
    dataset, or nothing visible, xyz_box null) those of its visible box."""
    box = info.get("xyz_box")
    return bop.box_pixels(info["bbox_visib"]) if box is None else tuple(int(v) for v in box)
