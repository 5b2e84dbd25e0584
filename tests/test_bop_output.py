"""scgen output read as bop_toolkit reads it: test targets, models_eval, vertex normals, depth, and
scene_gt_info in the toolkit's conventions, on real Mitsuba renders and the files they leave."""

from __future__ import annotations

import csv
import dataclasses
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

from posenet.config import smoke_config
from posenet.data import open_split
from posenet.data.crop import box_center
from scgen.annotate.annotate import covered_pixels, mask_bbox
from scgen.cli import main
from scgen.dataset.layout import Layout
from scgen.dataset.model_files import EVAL_MAX_EDGE_FRAC
from scgen.dataset.validate import validate_dataset
from scgen.dataset.writer import WriteOptions, finalize
from scgen.io import bop
from scgen.io.exr import read_xyz_exr
from scgen.render.base import create_backend
from scgen.scenes.config.scene import distance_range_m
from scgen.scenes.geometry import project
from scgen.scenes.model import load_target
from scgen.scenes.spec import CameraSpec, SceneSpec
from tests.conftest import SMALL, render_dataset

N, SEED = 24, 5  # seed 5 at 320x240: samples 0 and 16 are cut by the image border, 5 test samples
FLOAT32 = WriteOptions(xyz_dtype="float32")  # xyz exact enough to check depth to one unit


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return render_dataset(tmp_path_factory.mktemp("bop") / "ds", n=N, seed=SEED, write=FLOAT32)


def records(root: Path) -> list[dict]:
    return sorted((bop.read_json(p) for p in Layout(root).record_paths()), key=lambda r: r["sample_id"])


def read_png(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert img is not None, path
    return img


def masks(layout: Layout, rec: dict) -> tuple[np.ndarray, np.ndarray]:
    sid, split = rec["sample_id"], rec["split"]
    return read_png(layout.mask(split, sid)) > 0, read_png(layout.mask(split, sid, visib=True)) > 0


def test_test_targets_list_the_test_images_as_bop_toolkit_does(dataset: Path):
    tests = [r for r in records(dataset) if r["split"] == "test"]
    assert [r["sample_id"] for r in tests] == bop.read_json(dataset / "splits.json")["splits"]["test"]
    bop19 = bop.read_json(dataset / "test_targets_bop19.json")
    bop24 = bop.read_json(dataset / "test_targets_bop24.json")
    assert bop24 == [{"im_id": r["sample_id"], "scene_id": r["sample_id"] // 1000} for r in tests]
    visible = [r for r in tests if r["scene_gt_info"][0]["visib_fract"] >= 0.1]
    assert visible and bop19 == [
        {"im_id": r["sample_id"], "inst_count": 1, "obj_id": 1, "scene_id": r["sample_id"] // 1000}
        for r in visible
    ]
    layout = Layout(dataset)
    for target in bop19:  # the toolkit's criterion, on the masks: visible pixels over the whole projection
        rec = next(r for r in tests if r["sample_id"] == target["im_id"])
        _, visib = masks(layout, rec)
        assert visib.sum() >= 0.1 * rec["scene_gt_info"][0]["px_count_all"]


def test_test_targets_follow_an_interrupted_then_resumed_render(dataset: Path, tmp_path: Path):
    out = tmp_path / "resumed"
    shutil.copytree(dataset, out)
    layout = Layout(out)
    gone = bop.read_json(out / "splits.json")["splits"]["test"][:2]
    for sid in gone:  # as if the run had been killed before these two samples were written
        for f in layout.chunk_dir("test", sid).glob(f"*/{sid:06d}*"):
            f.unlink()
    finalize(layout)
    assert {t["im_id"] for t in bop.read_json(out / "test_targets_bop24.json")}.isdisjoint(gone)
    assert {t["im_id"] for t in bop.read_json(out / "test_targets_bop19.json")}.isdisjoint(gone)
    render_dataset(out, n=N, seed=SEED, write=FLOAT32)
    for name in ("test_targets_bop19.json", "test_targets_bop24.json", "test/000000/scene_gt_info.json"):
        assert (out / name).read_bytes() == (dataset / name).read_bytes(), name


def test_models_eval_samples_the_surface_densely_with_normals_and_colours(dataset: Path):
    info = bop.read_models_info(dataset)
    assert bop.read_json(dataset / "models_eval" / "models_info.json") == info
    diameter = info["1"]["diameter"] / 1000.0
    for folder in ("models", "models_eval"):  # what bop_toolkit's inout.load_ply looks for
        assert {"nx", "ny", "nz", "red", "green", "blue"} <= set(
            bop.ply_vertex_properties(dataset / folder / "obj_000001.ply")
        )
    cad = trimesh.load(str(dataset / "models" / "obj_000001.ply"), process=False)
    ev = trimesh.load(str(dataset / "models_eval" / "obj_000001.ply"), process=False)
    max_edge = EVAL_MAX_EDGE_FRAC * diameter * 1000.0  # mm
    assert ev.edges_unique_length.max() <= max_edge * (1 + 1e-6) < cad.edges_unique_length.max()
    assert len(ev.vertices) > 3 * len(cad.vertices)
    # every eval vertex lies on the CAD surface, and every surface point lies near an eval vertex
    assert np.abs(trimesh.proximity.ProximityQuery(cad).signed_distance(ev.vertices[::7])).max() < 1e-3
    points, _ = trimesh.sample.sample_surface(cad, 5000, seed=0)
    gap = trimesh.proximity.ProximityQuery(trimesh.PointCloud(ev.vertices)).vertex(points)[0]
    assert gap.max() <= max_edge / np.sqrt(3) + 1e-6
    # unit normals pointing out of the faces around them; the colour of each material kept
    for mesh in (cad, ev):
        n = mesh.vertex_normals
        assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-4)
        around = np.zeros_like(n)
        np.add.at(
            around, mesh.faces.ravel(), np.repeat(mesh.face_normals * mesh.area_faces[:, None], 3, axis=0)
        )
        assert (np.einsum("ij,ij->i", n, around) > 0).mean() > 0.999
    colours = {tuple(c) for c in cad.visual.vertex_colors[:, :3]}
    assert {tuple(c) for c in ev.visual.vertex_colors[:, :3]} == colours and len(colours) > 3


def test_depth_is_bop_depth_matching_the_xyz_maps_to_one_unit(dataset: Path):
    layout = Layout(dataset)
    cfg, model = bop.read_json(dataset / "config.json"), load_target()
    scale = bop.read_json(dataset / "camera.json")["depth_scale"]
    max_depth_mm = (
        distance_range_m(cfg, model.diameter)[1] + np.linalg.norm(model.mesh.vertices, axis=1).max()
    ) * 1000
    assert max_depth_mm / scale <= 65535 < max_depth_mm / (scale / 10)  # the smallest power of ten that fits
    assert np.log10(scale) == round(np.log10(scale))
    for rec in records(dataset):
        sid, split = rec["sample_id"], rec["split"]
        assert rec["scene_camera"]["depth_scale"] == scale
        depth = read_png(layout.depth(split, sid))
        assert depth.dtype == np.uint16 and depth.shape == (SMALL[1], SMALL[0])
        mask, visib = masks(layout, rec)
        assert (depth[mask] > 0).all()  # the target, or what hides it, always has a measurement
        if rec["scene_gt_info"][0]["xyz_box"] is None:
            continue
        x, y, w, h = rec["scene_gt_info"][0]["xyz_box"]
        vs, us = np.nonzero(visib[y : y + h, x : x + w])
        C = read_xyz_exr(layout.xyz(split, sid))[vs, us].astype(np.float64)
        R, t = bop.gt_pose(rec["scene_gt"][0])
        z_mm = (C @ R.T + t)[:, 2] * 1000.0
        assert np.abs(depth[vs + y, us + x] * scale - z_mm).max() <= scale


def test_gt_info_counts_the_whole_projection_as_bop_toolkit_renders_it(dataset: Path):
    """px_count_all and bbox_obj against the target rendered alone on bop_toolkit's 3W x 3H canvas."""
    layout = Layout(dataset)
    backend = create_backend("mitsuba", load_target(), quality="draft")
    W, H = SMALL
    cut = 0
    for rec in records(dataset):
        info = rec["scene_gt_info"][0]
        mask, visib = masks(layout, rec)
        spec = SceneSpec.from_dict(rec["spec"])
        K = spec.camera.K_mat
        wide = CameraSpec(
            3 * W, 3 * H, (K[0, 0], 0.0, K[0, 2] + W, 0.0, K[1, 1], K[1, 2] + H, 0.0, 0.0, 1.0), 0.0
        )
        whole = backend.render_geometry(dataclasses.replace(spec, camera=wide)).target_depth > 0
        assert (whole[H : 2 * H, W : 2 * W] == mask).all()  # the same ray casts, inside the image
        ys, xs = np.nonzero(whole)
        assert (
            info["px_count_all"] == len(xs) >= info["px_count_valid"] == mask.sum() >= info["px_count_visib"]
        )
        assert info["px_count_visib"] == visib.sum() > 0
        assert info["bbox_obj"] == [xs.min() - W, ys.min() - H, xs.max() - xs.min(), ys.max() - ys.min()]
        vys, vxs = np.nonzero(visib)
        assert info["bbox_visib"] == [vxs.min(), vys.min(), vxs.max() - vxs.min(), vys.max() - vys.min()]
        assert info["xyz_box"] == mask_bbox(visib)  # the crop keeps its meaning: pixels x .. x + w - 1
        assert info["visib_fract"] == pytest.approx(visib.sum() / len(xs))
        x, y, w, h = info["bbox_obj"]
        inside = x >= 0 and y >= 0 and x + w < W and y + h < H
        assert inside == (info["px_count_all"] == mask.sum())
        cut += not inside
    assert cut >= 2
    # metadata.csv keeps our own, clipped r_occ (paper eq. 9) for the occlusion groups
    with open(dataset / "metadata.csv") as f:
        for row, rec in zip(csv.DictReader(f), records(dataset), strict=True):
            mask, visib = masks(layout, rec)
            # 1.0 - n_vis / n_all of the same pixel counts (ints under 2^53: one correctly rounded quotient
            # and one subtraction either way), written as repr: the same float
            assert float(row["r_occ"]) == 1 - visib.sum() / mask.sum()
            assert int(row["px_count_all"]) == mask.sum()


def test_silhouette_raster_equals_the_renderers_mask_inside_the_image(dataset: Path):
    """The raster that measures the part past the border, checked where the renderer's mask exists."""
    layout, model = Layout(dataset), load_target()
    for rec in records(dataset):
        mask, _ = masks(layout, rec)
        R, t = bop.gt_pose(rec["scene_gt"][0])
        tri = project(bop.camera_K(rec["scene_camera"]), model.mesh.vertices @ R.T + t)[model.mesh.faces]
        assert (covered_pixels(tri, (0, 0, SMALL[0], SMALL[1])) == mask).all(), rec["sample_id"]


def test_posenet_crops_a_target_the_image_cuts(dataset: Path):
    cfg = smoke_config()
    data = dataclasses.replace(cfg.data, color_prob=0.0, bg_prob=0.0, dzi_prob=0.0)
    ds = open_split(dataset, "train", data, cfg.model_config(), train=True)
    for i, inst in enumerate(ds.instances):
        info = bop.read_json(dataset / "train" / "000000" / "scene_gt_info.json")[str(inst.im_id)][0]
        assert inst.bbox_obj == bop.box_pixels(info["bbox_obj"])
        x, y, w, h = info["bbox_obj"]
        item = ds[i]
        # no jitter (dzi_prob 0): box_center of whole pixels is a half-integer, exact in float64 and in the
        # item's float32, so equal
        assert np.array_equal(item["crop_center"].numpy(), [x + w / 2, y + h / 2])
        assert np.array_equal(box_center(inst.bbox_obj), [x + w / 2, y + h / 2])
        vis, full = item["roi_mask_visib"][0] > 0, item["roi_mask_full"][0] > 0
        assert vis.any() and bool(full[vis].all())
    assert any(b[0] < 0 or b[1] < 0 for b in (i.bbox_obj for i in ds.instances))


def test_validate_names_bad_bop_files(dataset: Path, tmp_path: Path):
    assert validate_dataset(dataset, progress=False) == ([], N)
    bad = tmp_path / "bad"
    shutil.copytree(dataset, bad)
    layout = Layout(bad)
    (bad / "test_targets_bop24.json").unlink()
    shutil.copy(bad / "models" / "obj_000001.ply", bad / "models_eval" / "obj_000001.ply")  # coarse CAD
    rec = records(bad)[3]
    sid, split = rec["sample_id"], rec["split"]
    depth = read_png(layout.depth(split, sid))
    cv2.imwrite(str(layout.depth(split, sid)), np.where(depth > 0, depth + 20, 0).astype(np.uint16))
    cut = records(bad)[0]  # clipped count, as scgen wrote it before: in the record and the scene file
    mask, _ = masks(layout, cut)
    cut["scene_gt_info"][0]["px_count_all"] = int(mask.sum())
    layout.record(cut["split"], 0).write_text(json.dumps(cut))
    infos_path = layout.chunk_dir(cut["split"], 0) / "scene_gt_info.json"
    infos = bop.read_json(infos_path)
    infos["0"] = cut["scene_gt_info"]
    infos_path.write_text(json.dumps(infos))
    problems, _ = validate_dataset(bad, progress=False)
    assert sorted(validate_dataset(bad, progress=False, workers=2)[0]) == sorted(problems)  # a process pool
    text = "\n".join(problems)
    assert "test_targets_bop24.json missing" in text
    assert "models_eval has an edge of" in text
    assert f"sample {sid}: depth differs from the xyz map" in text
    assert "sample 0: px_count_all" in text


def test_depth_flags(tmp_path: Path):
    base = [
        "render",
        "--n",
        "2",
        "--backend",
        "mitsuba",
        "--resolution",
        "160x120",
        "--quality",
        "draft",
        "--quiet",
    ]
    for flag, has_depth in (("--no-depth", False), ("--save-depth", True)):
        out = tmp_path / flag.strip("-")
        result = CliRunner().invoke(main, [*base, "--out", str(out), flag])
        assert result.exit_code == 0, result.output
        assert bop.read_json(out / "scgen.json")["save_depth"] is has_depth
        assert any(out.glob("*/*/depth/*.png")) is has_depth
        assert validate_dataset(out, progress=False)[0] == []
