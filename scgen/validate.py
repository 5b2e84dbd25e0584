"""`scgen validate`: re-check a dataset's invariants from the files alone and name every problem."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from scgen.annotate.annotate import mask_bbox
from scgen.dataset import Layout, open_dataset, read_json, read_metadata
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
    info = read_json(layout.root / "models" / "models_info.json")["1"]
    lo = np.array([info["min_x"], info["min_y"], info["min_z"]]) / 1000.0
    hi = lo + np.array([info["size_x"], info["size_y"], info["size_z"]]) / 1000.0
    records = list(layout.record_paths())
    if len(rows) != len(records):
        problems.append(f"metadata.csv has {len(rows)} rows but {len(records)} samples are on disk")
    for path in tqdm(records, desc="validate", unit="img", disable=not progress):
        rec = read_json(path)
        sid, split = rec["sample_id"], rec["split"]
        if split_of.get(sid) != split:
            problems.append(f"sample {sid}: in folder '{split}' but splits.json says '{split_of.get(sid)}'")
        if sid not in rows:
            problems.append(f"sample {sid}: missing from metadata.csv")
        problems += [f"sample {sid}: {p}" for p in check_sample(layout, manifest, rec, lo, hi)]
    return problems, len(records)


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
    gt = rec["scene_gt"][0]
    R = np.asarray(gt["cam_R_m2c"]).reshape(3, 3)
    t = np.asarray(gt["cam_t_m2c"]) / 1000.0
    K = np.asarray(rec["scene_camera"]["cam_K"]).reshape(3, 3)
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
