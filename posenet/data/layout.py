"""Index of a BOP-layout dataset directory (docs/dataset.md): one `Instance` per annotated target.

Only metadata is read here (JSON files); pixels are read lazily by the Dataset.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from posenet.data.io import image_fault
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
    dist: np.ndarray  # OpenCV's k1, k2, p1, p2, k3 (cam_dist; zeros: a pinhole camera)
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


def split_scenes(root: Path, split: str) -> list[Path]:
    """The scene folders of `root/split` that hold ground truth, in order (none: no such split)."""
    return sorted(p for p in (root / split).glob("[0-9]*") if _has_gt(p))


def object_ids(root: Path) -> list[int]:
    """The obj_ids of the dataset's objects (models/models_info.json's keys), in increasing order."""
    return sorted(int(k) for k in bop.read_models_info(root))


def scan_split(
    root: Path, split: str, obj_id: int, lens: bool = False, check_images: bool = True
) -> list[Instance]:
    """Every instance of object `obj_id` in `root/split/*/`, sorted by (scene_id, im_id, inst); the
    instances of other objects in the same images are skipped, their files never opened. An image taken
    through a lens is refused unless `lens` (posenet's crops and SITE are pinhole; predict warps lenses
    away). With `check_images`, every image the instances name must be whole (check_whole)."""
    size = image_size(root)
    scenes = split_scenes(root, split)
    if not scenes:
        found = sorted(
            p.name
            for p in root.iterdir()
            if p.is_dir() and any(p.glob("*/" + bop.scene_file(p, "scene_gt").name))
        )
        raise PosenetError(f"{root} has no split '{split}' (splits found: {', '.join(found) or 'none'})")
    out: list[Instance] = []
    for scene in scenes:
        out.extend(_scan_scene(scene, split, obj_id, size, lens))
    if check_images:
        check_whole(out, f"split '{split}' of {root}")
    return out


def check_whole(instances: list[Instance], where: str) -> None:
    """Refuse, before any work, images that are not whole (posenet.data.io.image_fault: their first and
    last bytes, under 0.1 ms an image, 4-5 s for 50,000). train, train-detector, eval and boxes all index
    their split through scan_split, so they refuse the same datasets; skipping instead would let eval score
    another image set than a run on the whole folder, and a broken copy rarely breaks one file only."""
    paths = sorted({i.rgb for i in instances})
    faults = [(p, why) for p in paths if (why := image_fault(p)) is not None]
    if faults:
        path, why = faults[0]
        record = path.parent.parent / "records" / f"{path.stem}.json"
        redo = (
            f"delete {record} and run its scgen render again, which renders the missing sample"
            if record.is_file()
            else "replace it, or delete it (its sample is then skipped, as one still being written)"
        )
        raise PosenetError(
            f"{len(faults)} of the {len(paths)} images of {where} cannot be read, e.g. {path}: {why}; {redo}"
        )


def _scan_scene(scene: Path, split: str, obj_id: int, size: tuple[int, int], lens: bool) -> list[Instance]:
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
            dist = np.asarray(bop.camera_dist(cams[im_key]), np.float64)
            if np.any(dist) and not lens:
                raise PosenetError(
                    f"{scene}: image {im_id} was taken through a lens with distortion (cam_dist "
                    f"{cams[im_key]['cam_dist']}); posenet's crops and SITE assume a pinhole camera: render "
                    "with a pinhole camera (scgen render --camera default) or undistort the images first"
                )
            K = bop.camera_K(cams[im_key])
            for inst, (ann, info) in enumerate(zip(gt[im_key], infos[im_key], strict=True)):
                if int(ann["obj_id"]) == obj_id:
                    out.append(_instance(scene, split, im_id, inst, rgb, (K, dist), ann, info, size))
    except (KeyError, ValueError, TypeError) as exc:
        raise PosenetError(f"{scene}: malformed BOP annotation ({type(exc).__name__}: {exc})") from exc
    return out


def _instance(
    scene: Path,
    split: str,
    im_id: int,
    inst: int,
    rgb: Path,
    camera: tuple[np.ndarray, np.ndarray],
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
        K=camera[0],
        dist=camera[1],
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
