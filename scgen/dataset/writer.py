"""Write samples in the BOP layout, atomically, and assemble the per-chunk JSON files at the end.

Each sample's files are written under temporary names and renamed; its record JSON goes last,
so a sample is either complete on disk or absent. `finalize` rebuilds scene_gt.json,
scene_camera.json, scene_gt_info.json, the test target lists and metadata.csv from the records in
sample order, so the result is byte-identical whatever the worker count, shard layout or resume point.
A sample is written against its dataset's static files: the depth scale of camera.json and the
model of models/, on which scene_gt_info's full projection is measured (what bop_toolkit renders).
"""

from __future__ import annotations

import csv
import functools
import io
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from scgen.annotate import Annotation
from scgen.annotate.record import exposure_ev, gt_info_entry, metadata_row
from scgen.dataset.layout import CHUNK, OBJ_ID, RGB_FORMATS, Layout, dumps
from scgen.errors import ScgenError
from scgen.io import bop
from scgen.io.atomic import atomic_write_bytes, atomic_write_text
from scgen.io.bop import read_json
from scgen.io.buffers import Buffers, CameraRecord
from scgen.io.exr import encode_xyz_exr
from scgen.scenes.attitude import CONE_COLUMNS
from scgen.scenes.config.scene import distance_range_m
from scgen.scenes.model import TargetModel
from scgen.scenes.spec import SEQUENCE_COLUMNS, Pose, SceneSpec

METADATA_COLUMNS = (
    "sample_id", "split", "scene_id", "im_id", "illumination", "sun_irradiance_w_m2", "exposure_ev",
    "sun_x", "sun_y", "sun_z", "shadow", "shadow_fraction", "shadow_caster", "occlusion", "r_occ",
    "visib_fract", "px_count_all", "px_count_visib", "requested_occlusion", "occluder_config", "n_occluders",
    "background", "background_holds", "distance_m", "tx", "ty", "tz", "qw", "qx", "qy", "qz",
    "viewpoint_cell", "combination_key",
    "camera", "noise", "noise_gain", "mid_grey_snr", "psf_fwhm_px", "motion_blur_px", "motion_blur_deg",
    "vignetting", "chromatic_px", "flare", "saturated",
    "finish", "earth_lat_deg", "earth_lon_deg", "sky_ra_deg", "sky_dec_deg",
)  # fmt: skip


UNDRAWN_JPEG_QUALITY = 95  # a JPEG's quality where the camera drew none (a spec without imaging)


@dataclass(frozen=True)
class WriteOptions:
    rgb_format: str = "auto"  # auto, png (lossless) or jpg (at the camera's drawn jpeg_quality)
    xyz_dtype: str = "float16"
    save_depth: bool = True  # BOP uint16 depth maps (bop_toolkit's calc_gt_info and VSD need them)


def dataset_depth_scale(
    cfg: dict[str, Any], models: Mapping[int, TargetModel],
    entries: Sequence[tuple[int, dict[str, Any]]] = (), frames: Sequence[SceneSpec] | None = None,
) -> float:  # fmt: skip
    """The dataset's depth scale (mm per unit): every labelled point fits, at the farthest distance each
    object is placed at plus its model's radius about its origin (|z| <= |t| + |v|); what lies farther is
    stored as 0. A sequence dataset (`frames`: every frame) takes its frames' poses; else the far end of
    the target's distance range (`models` by obj_id, the target's OBJ_ID) and of each `[[objects]]` entry's
    (`entries`: its obj_id and entry)."""
    radius = {k: float(np.linalg.norm(np.asarray(m.mesh.vertices), axis=1).max()) for k, m in models.items()}
    if frames is not None:
        reach = max(float(np.linalg.norm(s.target.t_vec)) for s in frames) + radius[OBJ_ID]
        for s in frames:
            for o in s.objects:
                reach = max(reach, float(np.linalg.norm(o.pose.t_vec)) + radius[o.obj_id])
        return bop.depth_scale_for(reach)
    reach = distance_range_m(cfg, models[OBJ_ID].diameter)[1] + radius[OBJ_ID]
    for obj_id, entry in entries:
        reach = max(
            reach, distance_range_m(cfg, models[obj_id].diameter, entry["distance"])[1] + radius[obj_id]
        )
    return bop.depth_scale_for(reach)


def dataset_target(layout: Layout, obj_id: int = OBJ_ID) -> tuple[np.ndarray, np.ndarray, float]:
    """(vertices in metres, faces, depth_scale): object `obj_id`'s models/ PLY and camera.json, read once
    per process and dataset (the files are written before any sample and never change)."""
    ply = layout.models_dir / bop.model_file(obj_id)
    return _read_target(layout.root, obj_id, _mtime(ply), _mtime(layout.camera_path))


def _mtime(path: Path) -> int:
    return path.stat().st_mtime_ns if path.exists() else -1


@functools.lru_cache(maxsize=16)
def _read_target(root: Path, obj_id: int, *_stamps: int) -> tuple[np.ndarray, np.ndarray, float]:
    mesh = bop.read_model_mesh(root, obj_id)
    depth_scale = float(read_json(Layout(root).camera_path)["depth_scale"])
    return np.asarray(mesh.vertices), np.asarray(mesh.faces), depth_scale


def rgb_format_for(requested: str, camera: dict[str, Any]) -> str:
    """The recorded images' file format: `requested` (png or jpg), or for auto the camera's: JPEG for an
    8-bit camera with a sensor model, PNG for an exact image (no sensor model, or 16 bits).

    Why: a sensor's noise is what a PNG keeps losslessly, at 12 times the bytes of a JPEG at the drawn
    quality (486 against 41 KB at 640x480), and the JPEG costs the network nothing measurable on the
    held-out split (docs/benchmarks.md, "What JPEG costs the network"); BOP's PBR images and SPEED+ ship
    as JPEG. An ideal camera's pixels are exact, compress well as PNG, and stay exact."""
    if requested not in RGB_FORMATS:
        raise ScgenError(f"unknown rgb format {requested!r} (choose {', '.join(RGB_FORMATS)})")
    if requested == "jpg" and camera["output"]["bits"] != 8:
        raise ScgenError("--rgb-format jpg holds 8 bits only: camera.output.bits is 16 (use png)")
    if requested != "auto":
        return requested
    return "jpg" if camera["sensor"]["enabled"] and camera["output"]["bits"] == 8 else "png"


def resolved(opts: WriteOptions, camera: dict[str, Any]) -> WriteOptions:
    """`opts` with its rgb format resolved for the camera (rgb_format_for): what a run writes with."""
    return replace(opts, rgb_format=rgb_format_for(opts.rgb_format, camera))


def drawn_jpeg_quality(spec: SceneSpec) -> int:
    """The JPEG quality the camera drew for the sample (UNDRAWN_JPEG_QUALITY for a spec without imaging)."""
    return spec.imaging.jpeg_quality if spec.imaging else UNDRAWN_JPEG_QUALITY


def encode_png(img: np.ndarray) -> bytes:
    """A PNG file of an 8- or 16-bit image (masks, depth, BGR colour)."""
    ok, buf = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, 3])
    assert ok
    return buf.tobytes()


def encode_rgb(image: np.ndarray, fmt: str, jpeg_quality: int = UNDRAWN_JPEG_QUALITY) -> bytes:
    """The recorded image's file: RGB (H x W x 3) or one channel (H x W), 8 or 16 bits (PNG only)."""
    bgr = image[..., ::-1] if image.ndim == 3 else image
    if fmt == "jpg":
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
        assert ok
        return buf.tobytes()
    return encode_png(bgr)


def write_sample(
    layout: Layout, spec: SceneSpec, buffers: Buffers, ann: Annotation, split: str, opts: WriteOptions,
    objects: Sequence[Annotation] = (),
) -> dict[str, Any]:  # fmt: skip
    """Write one sample's files atomically, record last; returns the record. `ann` is the target's labels,
    `objects` those of each of spec.objects: scene_gt entries 0, 1, ..."""
    sid = spec.index
    rgb_path = layout.rgb(split, sid, opts.rgb_format)
    rgb_path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(rgb_path, encode_rgb(buffers.rgb, opts.rgb_format, drawn_jpeg_quality(spec)))
    depth_scale = dataset_target(layout)[2]
    depth = bop.encode_depth(buffers.depth, depth_scale)
    if opts.save_depth:
        depth_path = layout.depth(split, sid)
        depth_path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(depth_path, encode_png(depth))
    others = ((o.obj_id, o.pose, a) for o, a in zip(spec.objects, objects, strict=True))
    instances = [(OBJ_ID, spec.target, ann), *others]
    gt_info = [write_instance(layout, spec, split, k, *inst, depth, opts) for k, inst in enumerate(instances)]
    record = build_record(spec, ann, split, gt_info, depth_scale, buffers.camera)
    record_path = layout.record(split, sid)
    record_path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(record_path, dumps(record))
    return record


def write_instance(
    layout: Layout, spec: SceneSpec, split: str, k: int, obj_id: int, pose: Pose, ann: Annotation,
    depth: np.ndarray, opts: WriteOptions,
) -> dict[str, Any]:  # fmt: skip
    """Write scene_gt instance k's masks and xyz map; returns its scene_gt_info entry (measured on its
    model in models/, what bop_toolkit renders)."""
    sid = spec.index
    for visib, mask in ((False, ann.mask), (True, ann.mask_visib)):
        path = layout.mask(split, sid, visib, k)
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, encode_png(mask.astype(np.uint8) * 255))
    xyz_box = None
    if ann.px_count_visib > 0:
        x, y, w, h = ann.bbox_visib
        xyz_box = [x, y, w, h]
        xyz_path = layout.xyz(split, sid, k)
        xyz_path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(xyz_path, encode_xyz_exr(ann.xyz[y : y + h, x : x + w], opts.xyz_dtype))
    vertices, faces, _ = dataset_target(layout, obj_id)
    vertices_cam = vertices @ pose.R_mat.T + pose.t_vec
    return gt_info_entry(spec.camera, ann, vertices_cam, faces, depth, xyz_box)


def build_record(
    spec: SceneSpec, ann: Annotation, split: str, gt_info: list[dict[str, Any]], depth_scale: float,
    camera: CameraRecord | None = None,
) -> dict[str, Any]:  # fmt: skip
    """Everything finalize needs for the BOP JSON files and the metadata row of one sample; `gt_info`: every
    instance's scene_gt_info entry (the target's first); `camera`: what the camera stage decided (None:
    the base exposure, no flare)."""
    scene_id = spec.sequence.sequence if spec.sequence else spec.index // CHUNK
    meta = metadata_row(spec, ann, split, scene_id, camera)
    exposure = exposure_ev(spec, camera)
    scene_camera = {"cam_K": list(spec.camera.K), "depth_scale": depth_scale, "exposure_ev": exposure}
    if not spec.camera.pinhole:
        scene_camera["cam_dist"] = list(spec.camera.dist)
    return {
        "sample_id": spec.index,
        "split": split,
        "scene_gt": [bop.gt_entry(spec.target.R_mat, spec.target.t_vec, OBJ_ID)]
        + [bop.gt_entry(o.pose.R_mat, o.pose.t_vec, o.obj_id) for o in spec.objects],
        "scene_camera": scene_camera,
        "scene_gt_info": gt_info,
        "metadata": meta,
        "spec": spec.to_dict(),
    }  # fmt: skip


def finalize(layout: Layout) -> int:
    """Assemble chunk JSON files, the test targets and metadata.csv from every record; returns the
    sample count. Reads one chunk's records at a time (from every split), so its memory stays that of a
    chunk however large the dataset; rows and targets come out in sample order."""
    by_chunk: dict[int, list[Path]] = defaultdict(list)
    for path in layout.record_paths():
        by_chunk[layout.scene_id(int(path.stem))].append(path)
    out = io.StringIO()
    writer: csv.DictWriter | None = None
    images: list[TargetImage] = []
    for chunk in sorted(by_chunk):
        records = sorted((read_json(p) for p in by_chunk[chunk]), key=lambda r: r["sample_id"])
        by_split: dict[str, list[dict[str, Any]]] = defaultdict(list)
        for r in records:
            by_split[r["split"]].append(r)
            if writer is None:
                writer = csv.DictWriter(out, fieldnames=metadata_columns(r), lineterminator="\n")
                writer.writeheader()
            writer.writerow({k: _fmt(r["metadata"][k]) for k in writer.fieldnames})
        for split, recs in by_split.items():
            d = layout.chunk_dir(split, recs[0]["sample_id"])
            for name in bop.SCENE_FILES:
                atomic_write_text(
                    bop.scene_file(d, name), dumps({str(r["sample_id"]): r[name] for r in recs})
                )
        images += target_images(by_split.get(bop.TEST_SPLIT, []))
    if writer is None:  # no sample yet: the header alone
        csv.DictWriter(out, fieldnames=METADATA_COLUMNS, lineterminator="\n").writeheader()
    for kind, targets in target_lists(images).items():
        atomic_write_text(layout.test_targets(kind), dumps(targets))
    atomic_write_text(layout.metadata_path, out.getvalue())
    return sum(len(paths) for paths in by_chunk.values())


def metadata_columns(record: dict[str, Any]) -> tuple[str, ...]:
    """metadata.csv's columns for a dataset holding `record`: every dataset's, then a cone attitude's
    (scgen.scenes.attitude.CONE_COLUMNS) when its samples were drawn in a cone, then a sequence frame's
    (scgen.scenes.spec.SEQUENCE_COLUMNS) when they are frames of sequences."""
    meta = record["metadata"]
    return (
        METADATA_COLUMNS
        + (CONE_COLUMNS if CONE_COLUMNS[0] in meta else ())
        + (SEQUENCE_COLUMNS if SEQUENCE_COLUMNS[0] in meta else ())
    )


TargetImage = tuple[int, int, list[dict[str, Any]], list[dict[str, Any]]]  # scene, image, scene_gt, gt_info


def target_images(test_records: list[dict[str, Any]]) -> list[TargetImage]:
    """(scene_id, im_id, scene_gt, scene_gt_info) of each test record, what the target lists read."""
    return [
        (r["metadata"]["scene_id"], r["sample_id"], r["scene_gt"], r["scene_gt_info"]) for r in test_records
    ]


def target_lists(images: list[TargetImage]) -> dict[str, list[dict[str, int]]]:
    """{"bop19": [...], "bop24": [...]}: the test target lists of these test images (in order)."""
    return {
        "bop19": bop.targets_bop19(images),
        "bop24": bop.targets_bop24([i[:2] for i in images]),
    }


def _fmt(v: Any) -> str:
    return repr(v) if isinstance(v, float) else str(v)


def existing_sample_ids(layout: Layout) -> set[int]:
    """Sample ids complete on disk (their record exists)."""
    return {int(p.stem) for p in layout.record_paths()}
