"""`scgen validate`: re-check a dataset's invariants from the files alone and name every problem."""

from __future__ import annotations

import contextlib
import functools
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from tqdm import tqdm

from scgen.annotate.annotate import full_projection
from scgen.dataset.bop_dataset import BopDataset, BopImage, is_bop_dataset, open_bop_dataset
from scgen.dataset.layout import Layout, open_dataset, read_metadata
from scgen.dataset.model_files import EVAL_MAX_EDGE_FRAC
from scgen.dataset.writer import TargetImage, dataset_target, target_images, target_lists
from scgen.errors import ScgenError
from scgen.io import bop
from scgen.io.bop import read_json
from scgen.io.exr import read_xyz_exr
from scgen.io.image_file import read_image, why_unreadable
from scgen.io.parent_watch import spawn_pool
from scgen.scenes.spec import CameraSpec

REPROJ_TOL_PX = 0.5
REPROJ_MIN_SHARE = 0.995


def validate_dataset(root: str | Path, progress: bool = True, workers: int = 1) -> tuple[list[str], int]:
    """(problems, number of samples checked); an empty problem list means the dataset is sound.

    The samples are checked one scene folder at a time, on `workers` processes when more than one.
    """
    if not Layout(root).manifest_path.is_file() and is_bop_dataset(Path(root)):
        return validate_bop_dataset(root, progress)  # a BOP dataset scgen did not render
    layout, manifest = open_dataset(root)
    problems = check_models(layout)
    table = read_metadata(root)
    rows = {int(r["sample_id"]) for r in table}
    if manifest.get("sequence"):
        problems += check_sequences(table, manifest["sequence"])
    splits = read_json(layout.splits_path)["splits"]
    split_of = {i: s for s, ids in splits.items() for i in ids}
    by_scene: dict[Path, list[Path]] = defaultdict(list)
    for path in layout.record_paths():
        by_scene[path.parent.parent].append(path)
    n = sum(len(paths) for paths in by_scene.values())
    if len(rows) != n:
        problems.append(f"metadata.csv has {len(rows)} rows but {n} samples are on disk")
    images: list[TargetImage] = []
    check = functools.partial(check_scene, layout.root)
    with (
        tqdm(total=n, desc="validate", unit="img", disable=not progress) as bar,
        spawn_pool(workers) if workers > 1 else contextlib.nullcontext() as pool,
    ):
        for seen, found, scene_images in (pool.map if pool else map)(check, list(by_scene.values())):
            for sid, split in seen:
                if split_of.get(sid) != split:
                    problems.append(
                        f"sample {sid}: in folder '{split}' but splits.json says '{split_of.get(sid)}'"
                    )
                if sid not in rows:
                    problems.append(f"sample {sid}: missing from metadata.csv")
            problems += found
            images += scene_images
            bar.update(len(seen))
    problems += check_test_targets(layout, sorted(images, key=lambda image: image[1]))
    return problems, n


def check_sequences(rows: list[dict[str, str]], sequence: dict[str, Any]) -> list[str]:
    """A sequence dataset's frames (metadata.csv): frame k of sequence s is sample s * frames + k, in BOP
    scene s, at time k * dt; every frame of a sequence in one split."""
    frames, dt = int(sequence["frames"]), float(sequence["dt_s"])
    out, splits = [], defaultdict(set)
    for r in rows:
        sid, seq, k = int(r["sample_id"]), int(r["sequence_id"]), int(r["frame"])
        splits[seq].add(r["split"])
        if (seq, k) != divmod(sid, frames) or int(r["scene_id"]) != seq:
            out.append(f"sample {sid}: sequence {seq}, frame {k}, scene {r['scene_id']}; its id gives "
                       f"sequence and scene {sid // frames}, frame {sid % frames}")  # fmt: skip
        if abs(float(r["time_s"]) - k * dt) > 1e-9 * max(1.0, k * dt):
            out.append(f"sample {sid}: time_s {r['time_s']} is not frame {k} x dt {dt}")
    out += [
        f"sequence {s}: frames in {', '.join(sorted(sp))}" for s, sp in sorted(splits.items()) if len(sp) > 1
    ]
    return out


def check_scene(
    root: Path, records: list[Path]
) -> tuple[list[tuple[int, str]], list[str], list[TargetImage]]:
    """Check the samples of one scene folder (their record files): ((sample id, split) of each record,
    problems, the test images among them)."""
    layout, manifest = open_dataset(root)
    models = object_models(layout)
    depth_scale = dataset_target(layout)[2]
    scene_files, problems = read_scene_files(records[0].parent.parent)
    seen, images = [], []
    for path in records:
        rec = read_json(path)
        sid, split = rec["sample_id"], rec["split"]
        seen.append((sid, split))
        if split == bop.TEST_SPLIT:
            images += target_images([rec])
        bop_problems = check_bop_entries(scene_files, rec)
        problems += [f"sample {sid}: {p}" for p in bop_problems]
        if not bop_problems:
            found = check_sample(layout, manifest, rec, models, depth_scale)
            problems += [f"sample {sid}: {p}" for p in found]
    return seen, problems, images


@dataclass(frozen=True)
class ObjectModel:
    """One obj_id's model as the checks read it: models/ PLY (vertices in metres, faces) and the
    models_info box (metres) its xyz values must lie in."""

    vertices: np.ndarray
    faces: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


def object_models(layout: Layout) -> dict[int, ObjectModel]:
    """obj_id -> its ObjectModel, for every object of models_info.json (check_models checks the files)."""
    out = {}
    for key, info in bop.read_models_info(layout.root).items():
        lo, size = bop.model_box_m(info)
        vertices, faces, _ = dataset_target(layout, int(key))
        out[int(key)] = ObjectModel(vertices, faces, lo, lo + size)
    return out


def check_models(layout: Layout) -> list[str]:
    """models/ and models_eval/, for every obj_id of models_info.json: PLYs with every vertex property
    bop_toolkit's load_ply reads, one models_info, and eval models with no edge over EVAL_MAX_EDGE_FRAC
    diameters (their vertices are the point sets of the toolkit's error functions)."""
    try:
        info = bop.read_models_info(layout.root)
    except ScgenError as exc:
        return [str(exc)]
    out = [p for obj_id in sorted(map(int, info)) for p in check_model_files(layout, obj_id)]
    if out:
        return out
    if read_json(layout.models_eval_dir / bop.MODELS_INFO_FILE) != info:
        out.append(f"{bop.MODELS_EVAL_DIR}/{bop.MODELS_INFO_FILE} differs from {bop.MODELS_DIR}/'s")
    for obj_id in sorted(map(int, info)):
        longest = bop.read_model_mesh(layout.root, obj_id, bop.MODELS_EVAL_DIR).edges_unique_length.max()
        limit = EVAL_MAX_EDGE_FRAC * info[str(obj_id)]["diameter"] / bop.MM_PER_M
        if longest > limit * (1 + 1e-6):  # the PLY holds float32 millimetres
            edge = f"{longest * bop.MM_PER_M:.2f} mm in {bop.model_file(obj_id)}"
            out.append(
                f"{bop.MODELS_EVAL_DIR} has an edge of {edge}, over {EVAL_MAX_EDGE_FRAC:.1%} of its diameter"
            )
    return out


def check_model_files(layout: Layout, obj_id: int) -> list[str]:
    """Object `obj_id`'s PLY in models/ and models_eval/: present, with every vertex property."""
    out = []
    for folder in (bop.MODELS_DIR, bop.MODELS_EVAL_DIR):
        ply = layout.root / folder / bop.model_file(obj_id)
        if not ply.is_file():
            out.append(f"{folder}/{ply.name} missing")
            continue
        missing = [p for p in bop.PLY_VERTEX_PROPERTIES if p not in bop.ply_vertex_properties(ply)]
        if missing:
            out.append(f"{folder}/{ply.name} has no vertex {', '.join(missing)}")
    return out


def check_test_targets(layout: Layout, images: list[TargetImage]) -> list[str]:
    """The test target lists at the root must list exactly the test samples on disk (in sample order)."""
    out = []
    for kind, expected in target_lists(images).items():
        path = layout.test_targets(kind)
        try:
            found = read_json(path)
        except ScgenError:
            out.append(f"{path.name} missing or unreadable")
            continue
        if found != expected:
            out.append(f"{path.name} has {len(found)} targets, the test samples on disk give {len(expected)} "
                       "(or the same number, different)")  # fmt: skip
    return out


def read_scene_files(scene: Path) -> tuple[dict[str, Any], list[str]]:
    """({name: content} of a scene folder's readable BOP JSON files, one problem per unreadable file)."""
    out: dict[str, Any] = {}
    problems = []
    for name in bop.SCENE_FILES:
        try:
            out[name] = read_json(bop.scene_file(scene, name))
        except ScgenError as exc:
            problems.append(str(exc))
    return out, problems


def check_bop_entries(scene_files: dict[str, Any], rec: dict[str, Any]) -> list[str]:
    """The BOP files (what posenet and bop_toolkit read) must hold exactly the sample's record; an
    unreadable file is reported once for its scene (read_scene_files), not per sample."""
    sid = str(rec["sample_id"])
    return [f"{name}.json entry missing or different from the sample's record"
            for name, content in scene_files.items() if content.get(sid) != rec[name]]  # fmt: skip


def check_sample(layout: Layout, manifest: dict[str, Any], rec: dict[str, Any],
                 models: dict[int, ObjectModel], depth_scale: float) -> list[str]:  # fmt: skip
    """Problems of one sample: the RGB and depth images, then every scene_gt instance against its own
    obj_id's model (check_instance; named "instance K (obj_id J)" where there are several), then the
    visible masks of the instances against each other."""
    sid, split = rec["sample_id"], rec["split"]
    rgb_path = layout.rgb(split, sid, manifest["rgb_format"])
    rgb = read_image(rgb_path)
    if rgb is None:
        return [f"cannot read {rgb_path}: {why_unreadable(rgb_path)}"]
    out: list[str] = []
    if rec["scene_camera"]["depth_scale"] != depth_scale:
        out.append(f"depth_scale {rec['scene_camera']['depth_scale']} != camera.json's {depth_scale}")
    depth = None
    if manifest["save_depth"]:
        depth_path = layout.depth(split, sid)
        depth = read_image(depth_path)
        if depth is None:
            return out + [f"cannot read {depth_path}: {why_unreadable(depth_path)}"]
        if depth.dtype != np.uint16 or depth.shape != rgb.shape[:2]:
            return out + [f"{depth_path} is not uint16 of the image size"]
    taken = np.zeros(rgb.shape[:2], np.int32)
    several = len(rec["scene_gt"]) > 1
    for k, gt in enumerate(rec["scene_gt"]):
        name = f"instance {k} (obj_id {gt['obj_id']}): " if several else ""
        if gt["obj_id"] not in models:
            out.append(f"{name}no entry in {bop.MODELS_DIR}/{bop.MODELS_INFO_FILE}")
            continue
        found, visib = check_instance(layout, manifest, rec, k, models[gt["obj_id"]], rgb.shape[:2], depth)
        out += [name + p for p in found]
        if visib is not None:
            taken += visib
    return out + overlap_problems(taken)


def check_instance(
    layout: Layout, manifest: dict[str, Any], rec: dict[str, Any], k: int, model: ObjectModel,
    size: tuple[int, int], depth: np.ndarray | None,
) -> tuple[list[str], np.ndarray | None]:  # fmt: skip
    """(problems, mask_visib or None where unreadable) of scene_gt instance k of a sample: its masks
    decode at the image size (H, W), mask inclusion, scene_gt_info against the masks and the model, xyz
    reprojection and bounds, depth against xyz."""
    sid, split = rec["sample_id"], rec["split"]
    paths = layout.mask(split, sid, inst=k), layout.mask(split, sid, visib=True, inst=k)
    mask, visib = bop.read_mask(paths[0]), bop.read_mask(paths[1])
    decoded = zip(paths, (mask, visib), strict=True)
    if unreadable := [f"cannot read {p}: {why_unreadable(p)}" for p, a in decoded if a is None]:
        return unreadable, None
    if mask.shape != size or visib.shape != size:
        return ["mask size differs from the RGB size"], None
    info = rec["scene_gt_info"][k]
    out = mask_inclusion(mask, visib)
    R, t = bop.gt_pose(rec["scene_gt"][k])
    camera = CameraSpec.from_scene_camera(rec["scene_camera"], size[1], size[0])
    whole = full_projection(mask, camera, model.vertices @ R.T + t, model.faces)
    valid = int(mask.sum()) if depth is None else int((mask & (depth > 0)).sum())
    out += check_gt_info(info, visib, whole, valid)
    if info["xyz_box"] is None:
        if visib.any():
            out.append("visible pixels but no xyz map")
        return out, visib
    xyz_path = layout.xyz(split, sid, inst=k)
    if not xyz_path.is_file():
        return out + [f"xyz map missing: {xyz_path}"], visib
    try:
        crop = read_xyz_exr(xyz_path)
    except Exception as exc:  # OpenEXR raises plain exceptions for corrupt files
        return out + [f"xyz map unreadable: {exc}"], visib
    x, y, w, h = info["xyz_box"]
    if crop.shape[:2] != (h, w):
        return out + [f"xyz map is {crop.shape[1]}x{crop.shape[0]}, box says {w}x{h}"], visib
    vis_crop = visib[y : y + h, x : x + w]
    out += check_xyz_support(crop, vis_crop)
    out += check_xyz(crop, vis_crop, (x, y), rec, k, model)
    if depth is not None:
        out += check_depth(depth[y : y + h, x : x + w], crop, vis_crop, rec, k, manifest["xyz_dtype"])
    return out, visib


def mask_inclusion(mask: np.ndarray, visib: np.ndarray) -> list[str]:
    """mask_visib must lie inside mask (the visible part of the whole silhouette)."""
    outside = int((visib & ~mask).sum())
    return [f"mask_visib has {outside} pixels outside mask"] if outside else []


def overlap_problems(taken: np.ndarray) -> list[str]:
    """`taken`: per pixel, how many instances' mask_visib hold it; one pixel shows one surface."""
    n = int((taken > 1).sum())
    return [f"visible masks of different instances overlap at {n} pixels"] if n else []


def check_gt_info(
    info: dict[str, Any], visib: np.ndarray, whole: tuple[int, list[int]], valid: int
) -> list[str]:
    """scene_gt_info in bop_toolkit's conventions: BOP boxes (w = max - min, -1 when nothing is visible),
    px_count_all and bbox_obj of the whole projection (`whole`, recomputed from the model), px_count_valid
    = mask pixels with a depth value (`valid`), visib_fract = px_count_visib / px_count_all."""
    expected = bop.gt_info_entry(*whole, visib, valid, info["xyz_box"])
    out = [
        f"{k} {info[k]} != {v} (from the masks and the model)"
        for k, v in expected.items()
        if k not in ("visib_fract", "xyz_box") and info[k] != v
    ]
    if not np.isclose(info["visib_fract"], expected["visib_fract"]):
        out.append(f"visib_fract {info['visib_fract']} != px_count_visib / px_count_all")
    return out


def check_depth(
    depth: np.ndarray, crop: np.ndarray, vis: np.ndarray, rec: dict[str, Any], k: int, xyz_dtype: str
) -> list[str]:
    """The depth image (cropped like the xyz map) must hold the z of the xyz map's points, K(R C + t):
    within half a depth unit, plus the rounding of the xyz map's own dtype (k: the scene_gt instance)."""
    R, t = bop.gt_pose(rec["scene_gt"][k])
    unit_m = rec["scene_camera"]["depth_scale"] / bop.MM_PER_M
    vs, us = np.nonzero(vis)
    C = crop[vs, us].astype(np.float64)
    rounding = np.sqrt(3) * float(np.finfo(xyz_dtype).eps) / 2 * np.abs(C).max(initial=0.0)
    err = np.abs(depth[vs, us] * unit_m - (C @ R.T + t)[:, 2])
    bad = int((err > 0.5 * unit_m + rounding + 1e-9).sum())
    return [f"depth differs from the xyz map's z at {bad} of {len(err)} visible pixels"] if bad else []


def check_xyz_support(crop: np.ndarray, vis: np.ndarray) -> list[str]:
    """An xyz map (crop) must be zero outside mask_visib (cropped alike): the labels of hidden pixels would
    teach a network the surface behind an occluder."""
    n = int((np.abs(crop).max(axis=-1) > 0)[~vis].sum())
    return [f"xyz map non-zero at {n} pixels outside mask_visib"] if n else []


def check_xyz(crop: np.ndarray, vis: np.ndarray, offset: tuple[int, int], rec: dict[str, Any], k: int,
              model: ObjectModel) -> list[str]:  # fmt: skip
    """xyz of scene_gt instance k must reproject onto its own pixels and lie inside its model's box."""
    R, t = bop.gt_pose(rec["scene_gt"][k])
    lo, hi = model.lo, model.hi
    camera = CameraSpec.from_scene_camera(rec["scene_camera"], *vis.shape[::-1])
    vs, us = np.nonzero(vis)
    C = crop[vs, us].astype(np.float64)
    err = reprojection_error(C, us + offset[0], vs + offset[1], camera, R, t)
    out = []
    share = float((err <= REPROJ_TOL_PX).mean()) if len(err) else 1.0
    if share < REPROJ_MIN_SHARE:
        out.append(f"xyz reprojects within {REPROJ_TOL_PX} px for only {share:.1%} of visible pixels")
    tol = 0.01 * float(np.max(hi - lo))
    outside = ((lo - tol > C) | (hi + tol < C)).any(axis=1)
    if outside.any():
        out.append(f"{int(outside.sum())} xyz values outside the model bounding box")
    return out


def reprojection_error(C: np.ndarray, u: np.ndarray, v: np.ndarray, camera: CameraSpec, R: np.ndarray,
                       t: np.ndarray) -> np.ndarray:  # fmt: skip
    """Pixel distance between the projection of R C + t (through the lens, if any) and the pixel centres
    (u, v) the coordinates were stored at."""
    uv = camera.project(C @ R.T + t)
    return np.hypot(uv[:, 0] - u, uv[:, 1] - v)


ON_MESH_TOL = 0.005  # fraction of the model diameter an xyz value may lie off the mesh
ON_MESH_SAMPLES = 1000  # xyz values per instance checked against the mesh (evenly strided)


def validate_bop_dataset(root: str | Path, progress: bool = True) -> tuple[list[str], int]:
    """BOP mode, for datasets scgen did not render (what `scgen annotate` writes): (problems, images).

    Every scene_gt instance has masks and a scene_gt_info entry agreeing with them, and an xyz map that
    is zero outside mask_visib, reprojects onto its own pixels and lies on the model's mesh;
    mask_visib ⊆ mask, and the visible masks of one image never overlap.
    """
    data = open_bop_dataset(Path(root))
    surfaces = {i: trimesh.proximity.ProximityQuery(bop.read_model_mesh(data.root, i)) for i in data.obj_ids}
    infos: dict[Path, dict[str, Any] | None] = {}
    problems: list[str] = []
    for image in tqdm(data.images, desc="validate", unit="img", disable=not progress):
        scene = data.scene(image)
        if scene not in infos:  # a file that cannot be read (a missing one too) is named once per scene
            files, unreadable = read_scene_files(scene)
            infos[scene] = files.get("scene_gt_info")
            problems += unreadable
        if infos[scene] is None:
            continue
        entries = infos[scene].get(str(image.im_id))
        if entries is None or len(entries) != len(image.instances):
            found = [] if entries is None else entries
            problems.append(f"{scene} image {image.im_id}: scene_gt_info.json has {len(found)} of "
                            f"{len(image.instances)} entries")  # fmt: skip
            continue
        found = check_bop_image(data, image, entries, surfaces)
        problems += [f"{scene} image {image.im_id}: {p}" for p in found]
    return problems, len(data.images)


def check_bop_image(data: BopDataset, image: BopImage, entries: list[dict[str, Any]],
                    surfaces: dict[int, trimesh.proximity.ProximityQuery]) -> list[str]:  # fmt: skip
    """Problems of one image's instances: masks against each other and scene_gt_info, then the xyz maps."""
    scene, (W, H) = data.scene(image), data.size
    taken = np.zeros((H, W), np.int32)
    out: list[str] = []
    for k, ((obj_id, R, t), info) in enumerate(zip(image.instances, entries, strict=True)):
        mask = bop.read_mask(bop.mask_path(scene, image.im_id, k))
        visib = bop.read_mask(bop.mask_path(scene, image.im_id, k, visib=True))
        if mask is None or visib is None or mask.shape != (H, W) or visib.shape != (H, W):
            out.append(f"instance {k}: mask or mask_visib missing, unreadable or not {W}x{H}")
            continue
        taken += visib
        problems = mask_inclusion(mask, visib)
        box_differs = bop.bbox(*np.nonzero(visib)[::-1]) != info["bbox_visib"]
        if int(visib.sum()) != info["px_count_visib"] or box_differs:
            problems.append("px_count_visib or bbox_visib differ from mask_visib")
        if info["px_count_all"] < mask.sum():
            problems.append(f"px_count_all {info['px_count_all']} below the mask's {int(mask.sum())} pixels")
        diameter = float(data.models_info[str(obj_id)]["diameter"]) / bop.MM_PER_M
        problems += check_bop_xyz(scene, image, k, visib, info, (R, t), surfaces[obj_id], diameter)
        out += [f"instance {k}: {p}" for p in problems]
    return out + overlap_problems(taken)


def check_bop_xyz(scene: Path, image: BopImage, k: int, visib: np.ndarray, info: dict[str, Any],
                  pose: tuple[np.ndarray, np.ndarray], surface: trimesh.proximity.ProximityQuery,
                  diameter: float) -> list[str]:  # fmt: skip
    """An instance's xyz map: present iff visible, the size of its xyz_box, zero outside mask_visib,
    reprojecting within REPROJ_TOL_PX and lying within ON_MESH_TOL diameters of the mesh."""
    box = info.get("xyz_box")
    if box is None:
        return ["visible pixels but no xyz_box"] if visib.any() else []
    path = bop.xyz_path(scene, image.im_id, k)
    try:
        crop = read_xyz_exr(path)
    except Exception as exc:  # OpenEXR raises plain exceptions for missing or corrupt files
        return [f"xyz map missing or unreadable ({path.name}: {exc})"]
    x, y, w, h = box
    vis_crop = visib[max(y, 0) : y + h, max(x, 0) : x + w]
    if crop.shape[:2] != (h, w) or vis_crop.shape != (h, w):
        return [f"xyz map is {crop.shape[1]}x{crop.shape[0]}, xyz_box {box} (inside the image) says {w}x{h}"]
    out = check_xyz_support(crop, vis_crop)
    vs, us = np.nonzero(vis_crop)
    if len(vs) == 0:
        return out
    C = crop[vs, us].astype(np.float64)
    camera = CameraSpec.from_scene_camera({"cam_K": image.K}, *visib.shape[::-1])
    err = reprojection_error(C, us + x, vs + y, camera, *pose)
    share = float((err <= REPROJ_TOL_PX).mean())
    if share < REPROJ_MIN_SHARE:
        out.append(f"xyz reprojects within {REPROJ_TOL_PX} px for only {share:.1%} of visible pixels")
    off = surface.on_surface(C[:: -(-len(C) // ON_MESH_SAMPLES)])[1] > ON_MESH_TOL * diameter
    if off.mean() > 1 - REPROJ_MIN_SHARE:
        out.append(f"{off.mean():.1%} of xyz values lie over {ON_MESH_TOL:.1%} of the diameter off the mesh")
    return out
