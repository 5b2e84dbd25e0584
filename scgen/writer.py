"""Write samples in the BOP layout, atomically, and assemble the per-chunk JSON files at the end.

Each sample's files are written under temporary names and renamed; its record JSON goes last,
so a sample is either complete on disk or absent. `finalize` rebuilds scene_gt.json,
scene_camera.json, scene_gt_info.json and metadata.csv from the records in sample order, so the
result is byte-identical whatever the worker count, shard layout or resume point.
"""

from __future__ import annotations

import csv
import io
from collections import defaultdict
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from scgen import bop
from scgen.annotate import Annotation
from scgen.atomic import atomic_write_bytes, atomic_write_text
from scgen.bop import read_json
from scgen.buffers import Buffers
from scgen.dataset import CHUNK, OBJ_ID, Layout, dumps
from scgen.exr import encode_xyz_exr
from scgen.factors import occluder_config, spec_key
from scgen.scenes.geometry import matrix_to_quat
from scgen.scenes.spec import SceneSpec
from scgen.splits import viewpoint_cell

DEPTH_SCALES = (0.01, 0.1, 1.0, 10.0)  # mm per depth unit; the smallest that cannot wrap is chosen
METADATA_COLUMNS = (
    "sample_id", "split", "scene_id", "im_id", "illumination", "sun_irradiance_w_m2", "exposure_ev",
    "sun_x", "sun_y", "sun_z", "shadow", "shadow_fraction", "shadow_caster", "occlusion", "r_occ",
    "visib_fract", "px_count_all", "px_count_visib", "requested_occlusion", "occluder_config", "n_occluders",
    "background", "distance_m", "tx", "ty", "tz", "qw", "qx", "qy", "qz", "viewpoint_cell", "combination_key",
)  # fmt: skip


@dataclass(frozen=True)
class WriteOptions:
    rgb_format: str = "png"  # png (lossless) or jpg
    xyz_dtype: str = "float16"
    save_depth: bool = False


def choose_depth_scale(depth_m: np.ndarray) -> float:
    """Smallest BOP depth_scale (mm per unit) for which the largest depth fits in uint16."""
    max_mm = float(depth_m.max()) * bop.MM_PER_M if depth_m.size else 0.0
    for scale in DEPTH_SCALES:
        if max_mm / scale <= 65535:
            return scale
    raise ValueError(f"depth {max_mm:.0f} mm does not fit uint16 at any depth scale")


def _png(img: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, 3])
    assert ok
    return buf.tobytes()


def encode_rgb(rgb: np.ndarray, fmt: str) -> bytes:
    if fmt == "jpg":
        ok, buf = cv2.imencode(".jpg", rgb[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 95])
        assert ok
        return buf.tobytes()
    return _png(rgb[..., ::-1])


def write_sample(
    layout: Layout, spec: SceneSpec, buffers: Buffers, ann: Annotation, split: str, opts: WriteOptions
) -> dict[str, Any]:
    """Write one sample's files atomically, record last; returns the record."""
    sid = spec.index
    paths = {
        "rgb": layout.rgb(split, sid, opts.rgb_format),
        "mask": layout.mask(split, sid),
        "mask_visib": layout.mask(split, sid, visib=True),
    }
    for p in paths.values():
        p.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(paths["rgb"], encode_rgb(buffers.rgb, opts.rgb_format))
    atomic_write_bytes(paths["mask"], _png(ann.mask.astype(np.uint8) * 255))
    atomic_write_bytes(paths["mask_visib"], _png(ann.mask_visib.astype(np.uint8) * 255))
    xyz_box = None
    if ann.px_count_visib > 0:
        x, y, w, h = ann.bbox_visib
        xyz_box = [x, y, w, h]
        xyz_path = layout.xyz(split, sid)
        xyz_path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(xyz_path, encode_xyz_exr(ann.xyz[y : y + h, x : x + w], opts.xyz_dtype))
    depth_scale = 1.0
    if opts.save_depth:
        depth_scale = choose_depth_scale(buffers.depth)
        depth_path = layout.depth(split, sid)
        depth_path.parent.mkdir(parents=True, exist_ok=True)
        depth_u16 = np.round(buffers.depth * bop.MM_PER_M / depth_scale).astype(np.uint16)
        atomic_write_bytes(depth_path, _png(depth_u16))
    record = build_record(spec, ann, split, xyz_box, depth_scale)
    record_path = layout.record(split, sid)
    record_path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(record_path, dumps(record))
    return record


def build_record(
    spec: SceneSpec, ann: Annotation, split: str, xyz_box: list[int] | None, depth_scale: float
) -> dict[str, Any]:
    """Everything finalize needs for the BOP JSON files and the metadata row of one sample."""
    R, t = spec.target.R_mat, spec.target.t_vec
    q = matrix_to_quat(R)
    sun = spec.sun.direction
    meta = {
        "sample_id": spec.index,
        "split": split,
        "scene_id": spec.index // CHUNK,
        "im_id": spec.index,
        "illumination": spec.sun.level,
        "sun_irradiance_w_m2": spec.sun.irradiance,
        "exposure_ev": spec.camera.exposure_ev,
        "sun_x": sun[0],
        "sun_y": sun[1],
        "sun_z": sun[2],
        "shadow": ann.shadow_label,
        "shadow_fraction": ann.shadow_fraction,
        "shadow_caster": int(spec.shadow_caster),
        "occlusion": ann.occlusion_group,
        "r_occ": ann.r_occ,
        "visib_fract": ann.visib_fract,
        "px_count_all": ann.px_count_all,
        "px_count_visib": ann.px_count_visib,
        "requested_occlusion": spec.requested_occlusion,
        "occluder_config": occluder_config(spec),
        "n_occluders": len(spec.occluders),
        "background": spec.background.kind,
        "distance_m": spec.distance_m,
        "tx": t[0],
        "ty": t[1],
        "tz": t[2],
        "qw": q[0],
        "qx": q[1],
        "qy": q[2],
        "qz": q[3],
        "viewpoint_cell": viewpoint_cell(R, t),
        "combination_key": spec_key(spec),
    }
    return {
        "sample_id": spec.index,
        "split": split,
        "scene_gt": [bop.gt_entry(R, t, OBJ_ID)],
        "scene_camera": {"cam_K": list(spec.camera.K), "depth_scale": depth_scale,
                         "exposure_ev": spec.camera.exposure_ev},
        "scene_gt_info": [{"bbox_obj": ann.bbox_obj, "bbox_visib": ann.bbox_visib,
                           "px_count_all": ann.px_count_all, "px_count_valid": ann.px_count_all,
                           "px_count_visib": ann.px_count_visib, "visib_fract": ann.visib_fract,
                           "xyz_box": xyz_box}],
        "metadata": meta,
        "spec": spec.to_dict(),
    }  # fmt: skip


def finalize(layout: Layout) -> int:
    """Assemble chunk JSON files and metadata.csv from every record; returns the sample count."""
    records = [read_json(p) for p in layout.record_paths()]
    records.sort(key=lambda r: r["sample_id"])
    chunks: dict[tuple[str, int], list[dict[str, Any]]] = defaultdict(list)
    for r in records:
        chunks[(r["split"], r["sample_id"] // CHUNK)].append(r)
    for (split, _), recs in chunks.items():
        d = layout.chunk_dir(split, recs[0]["sample_id"])
        for name in bop.SCENE_FILES:
            atomic_write_text(bop.scene_file(d, name), dumps({str(r["sample_id"]): r[name] for r in recs}))
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=METADATA_COLUMNS, lineterminator="\n")
    writer.writeheader()
    for r in records:
        writer.writerow({k: _fmt(r["metadata"][k]) for k in METADATA_COLUMNS})
    atomic_write_text(layout.metadata_path, out.getvalue())
    return len(records)


def _fmt(v: Any) -> str:
    return repr(v) if isinstance(v, float) else str(v)


def existing_sample_ids(layout: Layout) -> set[int]:
    """Sample ids complete on disk (their record exists)."""
    return {int(p.stem) for p in layout.record_paths()}
