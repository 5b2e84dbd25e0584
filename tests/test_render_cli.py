"""`scgen render` / `scgen validate` end to end on real Mitsuba renders, plus bad-input handling."""

from __future__ import annotations

import csv
import filecmp
import json
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

from scgen.annotate import annotate
from scgen.cli import main
from scgen.dataset.layout import Layout
from scgen.io.bop import read_json
from scgen.io.exr import encode_xyz_exr, read_xyz_exr
from scgen.render.base import create_backend
from scgen.scenes import SceneSpec, load_config, sample_scene
from scgen.scenes.model import load_target
from scgen.scenes.silhouette import TargetShape
from tests.conftest import SMALL, render_dataset


def run(*args: str):
    return CliRunner().invoke(main, list(args), catch_exceptions=False)


def tree_files(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())


def test_dataset_has_bop_layout_and_one_metadata_row_per_image(small_dataset: Path):
    files = tree_files(small_dataset)
    for name in ("camera.json", "scgen.json", "splits.json", "metadata.csv", "config.json",
                 "models/obj_000001.ply", "models/models_info.json"):  # fmt: skip
        assert name in files
    with open(small_dataset / "metadata.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["sample_id"]) for r in rows] == list(range(12))
    for column in ("illumination", "shadow", "occlusion", "background", "distance_m", "combination_key"):
        assert all(r[column] != "" for r in rows)
    assert len([f for f in files if "/rgb/" in f]) == 12
    info = read_json(small_dataset / "models" / "models_info.json")["1"]
    # the bundled model was scaled to 0.2 m and stored as float32 vertices (u32 |p| each): its farthest pair
    # within 2 u32 x 0.2 m, so 1.2e-7 relative, then x 1000 (a u64)
    assert info["diameter"] == pytest.approx(200.0, rel=1e-6)


def test_sample_rendered_alone_equals_sample_from_the_run(small_dataset: Path):
    model = load_target()
    cfg = load_config(resolution=SMALL)
    spec = sample_scene(0, 7, cfg, TargetShape.from_mesh(model.mesh, model.diameter))
    ann = annotate(spec, create_backend("mitsuba", model, quality="draft").render(spec))
    layout = Layout(small_dataset)
    split = _split(layout, 7)
    mask = cv2.imread(str(layout.mask(split, 7)), cv2.IMREAD_UNCHANGED) > 0
    visib = cv2.imread(str(layout.mask(split, 7, visib=True)), cv2.IMREAD_UNCHANGED) > 0
    assert (mask == ann.mask).all() and (visib == ann.mask_visib).all()
    x, y, w, h = ann.bbox_visib
    xyz = read_xyz_exr(layout.xyz(split, 7))
    assert np.array_equal(xyz, ann.xyz[y : y + h, x : x + w].astype(np.float16))  # the EXR's half floats


def test_same_seed_gives_identical_annotations(small_dataset: Path, tmp_path: Path):
    again = render_dataset(tmp_path / "again", n=12)
    for name in tree_files(small_dataset):
        if "/rgb/" in name:
            continue  # RGB path tracing is seeded too, but annotations are the contract here
        assert filecmp.cmp(small_dataset / name, again / name, shallow=False), name


def test_validate_passes_then_names_tampered_files(small_dataset: Path, tmp_path: Path):
    assert run("validate", str(small_dataset)).exit_code == 0
    bad = tmp_path / "bad"
    shutil.copytree(small_dataset, bad)
    layout = Layout(bad)
    split = next(s for s in ("train", "val", "test") if layout.record(s, 3).exists())
    mask_path = layout.mask(split, 3, visib=True)
    m = cv2.imread(str(mask_path), cv2.IMREAD_UNCHANGED)
    m[:5, :5] = 255
    cv2.imwrite(str(mask_path), m)
    xyz_sample = next(i for i in range(12) if i != 3 and layout.xyz(_split(layout, i), i).exists())
    xyz_path = layout.xyz(_split(layout, xyz_sample), xyz_sample)
    xyz_path.write_bytes(encode_xyz_exr(read_xyz_exr(xyz_path) + 0.01))
    gt_sample = next(i for i in range(12) if i not in (3, xyz_sample))
    gt_path = layout.chunk_dir(_split(layout, gt_sample), gt_sample) / "scene_gt.json"
    gt = read_json(gt_path)
    gt[str(gt_sample)][0]["cam_t_m2c"][2] += 10.0  # what posenet would read: 1 cm further away
    gt_path.write_text(json.dumps(gt))
    result = CliRunner().invoke(main, ["validate", str(bad)])
    assert result.exit_code != 0
    assert "sample 3: mask_visib has" in result.output
    assert f"sample {xyz_sample}: xyz reprojects" in result.output
    assert f"sample {gt_sample}: scene_gt.json entry missing or different" in result.output


def _split(layout: Layout, i: int) -> str:
    return next(s for s in ("train", "val", "test") if layout.record(s, i).exists())


def _bad_meshes(tmp: Path) -> dict[str, Path]:
    corrupt = tmp / "corrupt.ply"
    corrupt.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 99\n\x00\x01garbage")
    empty = tmp / "empty.obj"
    empty.write_text("# no geometry\n")
    return {"missing": tmp / "nope.obj", "corrupt": corrupt, "empty": empty}


@pytest.mark.parametrize(
    "args, message",
    [
        (["--n", "0"], "--n must be a positive"),
        (["--n", "-3"], "--n must be a positive"),
        (["--n", "2", "--backend", "povray"], "unknown backend 'povray'"),
        (["--n", "2", "--resolution", "0x480"], "--resolution"),
        (["--n", "2", "--model", "{missing}"], "mesh not found"),
        (["--n", "2", "--model", "{corrupt}"], "corrupt.ply"),
        (["--n", "2", "--model", "{empty}"], "empty.obj"),
        (["--n", "2", "--config", "{badkey}"], "unknown config key 'shadow.nope'"),
        (["--n", "2", "--split", "0.5,0.5,0.5"], "summing to 1"),
    ],
)
def test_bad_input_is_one_line_error_and_writes_nothing(tmp_path: Path, args, message):
    paths = {k: str(v) for k, v in _bad_meshes(tmp_path).items()}
    (tmp_path / "bad.toml").write_text("[shadow]\nnope = 1\n")
    paths["badkey"] = str(tmp_path / "bad.toml")
    out = tmp_path / "out"
    args = [a.format(**paths) for a in args]
    backend = [] if "--backend" in args else ["--backend", "mitsuba"]
    result = CliRunner().invoke(main, ["render", "--out", str(out), *backend, *args])
    assert result.exit_code != 0
    lines = [ln for ln in result.output.strip().splitlines() if ln]
    assert len(lines) == 1 and message in lines[0], result.output
    assert not out.exists()


def test_output_that_is_a_file_is_refused(tmp_path: Path):
    out = tmp_path / "file.txt"
    out.write_text("x")
    result = CliRunner().invoke(main, ["render", "--n", "1", "--out", str(out), "--backend", "mitsuba"])
    assert result.exit_code != 0 and "is not a directory" in result.output
    assert out.read_text() == "x"


def test_user_mesh_is_normalised(tmp_path: Path):
    mesh_path = tmp_path / "box.stl"
    trimesh.creation.box(extents=[3.0, 1.0, 2.0]).export(str(mesh_path))
    # the corners (+-1.5, +-0.5, +-1) are exact in the STL's float32, so the diameter is sqrt(9 + 1 + 4)
    # correctly rounded; scaled to 0.2 m it is d x (0.2 / d), two roundings: within 2 u64 of 0.2
    assert load_target(mesh_path).diameter == pytest.approx(0.2, rel=1e-15)
    assert load_target(mesh_path, keep_scale=True).diameter == np.sqrt(14)


def test_saved_depth_round_trips_without_wrapping(small_dataset: Path):
    """Depth is on by default, one scale per dataset; what lies beyond its range is 0, never wrapped."""
    layout, model = Layout(small_dataset), load_target()
    backend = create_backend("mitsuba", model, quality="draft")
    for i in range(3):
        split = _split(layout, i)
        scale = read_json(layout.record(split, i))["scene_camera"]["depth_scale"]
        assert scale == read_json(layout.camera_path)["depth_scale"]
        stored = cv2.imread(str(layout.depth(split, i)), cv2.IMREAD_UNCHANGED)
        assert stored.dtype == np.uint16
        spec = SceneSpec.from_dict(read_json(layout.record(split, i))["spec"])
        depth = backend.render(spec).depth
        fits = depth * 1000.0 / scale <= 65535
        assert np.abs(stored * scale / 1000.0 - depth)[fits].max() <= 0.5 * scale / 1000.0 + 1e-6
        assert (stored[~fits] == 0).all() and fits[depth <= spec.distance_m + model.diameter].all()


def test_validate_names_each_unreadable_file_once_with_its_cause(small_dataset: Path, tmp_path: Path):
    """A PNG cut in half (libpng's own "Read Error" line stays off the terminal), an empty depth PNG and a
    truncated scene_gt.json: one FAIL line each, naming the file and what is wrong with it."""
    bad = tmp_path / "bad"
    shutil.copytree(small_dataset, bad)
    layout = Layout(bad)
    manifest = read_json(layout.manifest_path)
    ids = sorted(int(p.stem) for p in layout.record_paths())
    rgb = layout.rgb(_split(layout, ids[0]), ids[0], manifest["rgb_format"])
    rgb.write_bytes(rgb.read_bytes()[: rgb.stat().st_size // 2])
    depth = layout.depth(_split(layout, ids[1]), ids[1])
    depth.write_bytes(b"")
    gt_path = layout.chunk_dir(_split(layout, ids[2]), ids[2]) / "scene_gt.json"
    gt_path.write_text(gt_path.read_text()[:200])
    command = [sys.executable, "-m", "scgen.cli", "validate", str(bad), "--quiet", "--workers", "1"]
    done = subprocess.run(command, capture_output=True, text=True)
    fails = [ln for ln in done.stdout.splitlines() if ln.startswith("FAIL")]
    assert done.returncode == 1 and "libpng" not in done.stderr + done.stdout, done.stderr
    assert f"FAIL sample {ids[0]}: cannot read {rgb}: truncated or not an image" in fails
    assert f"FAIL sample {ids[1]}: cannot read {depth}: empty file" in fails
    gt_fails = [ln for ln in fails if str(gt_path) in ln]
    assert len(gt_fails) == 1 and "Expecting" in gt_fails[0], fails  # json's own words, once
    assert len(fails) == 3, fails
