"""`scgen validate`: re-check a dataset's invariants from the files alone and name every problem."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from scgen import bop
from scgen.annotate.annotate import mask_bbox
from scgen.bop import read_json
from scgen.dataset import OBJ_ID, Layout, open_dataset, read_metadata
from scgen.errors import ScgenError
from scgen.exr import read_xyz_exr
from scgen.scenes.geometry import project

REPROJ_TOL_PX = 0.5
REPROJ_MIN_SHARE = 0.995


def validate_dataset(root: str | Path, progress: bool = True) -> tuple[list[str], int]:
    """(problems, number of samples checked); an empty problem list means the dataset is sound."""
    layout, manifest = open_dataset(root)
    problems: list[str] = []
    rows = {int(r["sample_id"]): r for r in read_metadata(root)}
    splits = read_json(layout.splits_path)["splits"]
    split_of = {i: s for s, ids in splits.items() for i in ids}
    lo, size = bop.model_box_m(bop.read_models_info(layout.root)[str(OBJ_ID)])
    records = list(layout.record_paths())
    if len(rows) != len(records):
        problems.append(f"metadata.csv has {len(rows)} rows but {len(records)} samples are on disk")
    scene_files: dict[Path, dict[str, Any]] = {}
    for path in tqdm(records, desc="validate", unit="img", disable=not progress):
        rec = read_json(path)
        sid, split = rec["sample_id"], rec["split"]
        if split_of.get(sid) != split:
            problems.append(f"sample {sid}: in folder '{split}' but splits.json says '{split_of.get(sid)}'")
        if sid not in rows:
            problems.append(f"sample {sid}: missing from metadata.csv")
        scene = layout.chunk_dir(split, sid)
        if scene not in scene_files:
            scene_files[scene] = read_scene_files(scene)
        bop_problems = check_bop_entries(scene_files[scene], rec)
        problems += [f"sample {sid}: {p}" for p in bop_problems]
        if not bop_problems:
            problems += [f"sample {sid}: {p}" for p in check_sample(layout, manifest, rec, lo, lo + size)]
    return problems, len(records)


def read_scene_files(scene: Path) -> dict[str, Any]:
    """{name: content} of a scene folder's BOP JSON files (None where missing or unreadable)."""
    out: dict[str, Any] = {}
    for name in bop.SCENE_FILES:
        path = bop.scene_file(scene, name)
        try:
            out[name] = read_json(path)
        except ScgenError:
            out[name] = None
    return out


def check_bop_entries(scene_files: dict[str, Any], rec: dict[str, Any]) -> list[str]:
    """The BOP files (what posenet and bop_toolkit read) must hold exactly the sample's record."""
    out = []
    for name, content in scene_files.items():
        if content is None:
            out.append(f"{name}.json missing or unreadable")
        elif content.get(str(rec["sample_id"])) != rec[name]:
            out.append(f"{name}.json entry missing or different from the sample's record")
    return out


def _read_mask(path: Path) -> np.ndarray | None:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    return None if img is None else img > 127


def check_sample(layout: Layout, manifest: dict[str, Any], rec: dict[str, Any], lo: np.ndarray,
                 hi: np.ndarray) -> list[str]:  # fmt: skip
    """Problems of one sample: files, mask inclusion, boxes and counts, xyz reprojection and bounds."""
    sid, split = rec["sample_id"], rec["split"]
    out: list[str] = []
    rgb_path = layout.rgb(split, sid, manifest["rgb_format"])
    rgb = cv2.imread(str(rgb_path), cv2.IMREAD_COLOR)
    mask = _read_mask(layout.mask(split, sid))
    visib = _read_mask(layout.mask(split, sid, visib=True))
    if rgb is None or mask is None or visib is None:
        return [f"unreadable or missing image/mask ({rgb_path.parent.parent})"]
    if mask.shape != rgb.shape[:2] or visib.shape != rgb.shape[:2]:
        out.append("mask size differs from the RGB size")
        return out
    info = rec["scene_gt_info"][0]
    if (visib & ~mask).any():
        out.append(f"mask_visib has {int((visib & ~mask).sum())} pixels outside mask")
    if mask_bbox(mask) != info["bbox_obj"]:
        out.append(f"bbox_obj {info['bbox_obj']} != mask extent {mask_bbox(mask)}")
    if mask_bbox(visib) != info["bbox_visib"]:
        out.append(f"bbox_visib {info['bbox_visib']} != mask_visib extent {mask_bbox(visib)}")
    if int(mask.sum()) != info["px_count_all"] or int(visib.sum()) != info["px_count_visib"]:
        out.append("pixel counts differ from the masks")
    if info["xyz_box"] is None:
        if visib.any():
            out.append("visible pixels but no xyz map")
        return out
    xyz_path = layout.xyz(split, sid)
    if not xyz_path.is_file():
        return out + [f"xyz map missing: {xyz_path}"]
    try:
        crop = read_xyz_exr(xyz_path)
    except Exception as exc:  # OpenEXR raises plain exceptions for corrupt files
        return out + [f"xyz map unreadable: {exc}"]
    x, y, w, h = info["xyz_box"]
    if crop.shape[:2] != (h, w):
        return out + [f"xyz map is {crop.shape[1]}x{crop.shape[0]}, box says {w}x{h}"]
    vis_crop = visib[y : y + h, x : x + w]
    if np.abs(crop[~vis_crop]).max(initial=0) > 0:
        out.append("xyz map non-zero outside mask_visib")
    out += check_xyz(crop, vis_crop, (x, y), rec, lo, hi)
    return out


def check_xyz(crop: np.ndarray, vis: np.ndarray, offset: tuple[int, int], rec: dict[str, Any],
              lo: np.ndarray, hi: np.ndarray) -> list[str]:  # fmt: skip
    """xyz must reproject onto its own pixels and lie inside the model's bounding box."""
    R, t = bop.gt_pose(rec["scene_gt"][0])
    K = bop.camera_K(rec["scene_camera"])
    vs, us = np.nonzero(vis)
    C = crop[vs, us].astype(np.float64)
    err = reprojection_error(C, us + offset[0], vs + offset[1], K, R, t)
    out = []
    share = float((err <= REPROJ_TOL_PX).mean()) if len(err) else 1.0
    if share < REPROJ_MIN_SHARE:
        out.append(f"xyz reprojects within {REPROJ_TOL_PX} px for only {share:.1%} of visible pixels")
    tol = 0.01 * float(np.max(hi - lo))
    outside = ((lo - tol > C) | (hi + tol < C)).any(axis=1)
    if outside.any():
        out.append(f"{int(outside.sum())} xyz values outside the model bounding box")
    return out


def reprojection_error(C: np.ndarray, u: np.ndarray, v: np.ndarray, K: np.ndarray, R: np.ndarray,
                       t: np.ndarray) -> np.ndarray:  # fmt: skip
    """Pixel distance between K(R C + t) and the pixel centres (u, v) the coordinates were stored at."""
    uv = project(K, C @ R.T + t)
    return np.hypot(uv[:, 0] - u, uv[:, 1] - v)
