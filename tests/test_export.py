"""`scgen export` on a real Mitsuba render, checked with the formats' own clients: pycocotools decodes and
scores the COCO files; the SPEED+ poses, rebuilt by another route (scipy's quaternion, OpenCV's
projection), land on the BOP pose's projection."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval
from scipy.spatial.transform import Rotation

from scgen.cli import main
from scgen.dataset.export import FORMATS
from scgen.dataset.export.output import ExportFormat
from scgen.dataset.export.source import Source
from scgen.dataset.layout import Layout, read_metadata
from scgen.io import bop
from tests.conftest import SEQUENCE

# SPEED+'s own camera.json distortion (k1, k2, p1, p2, k3), as a cam_dist the exporter must carry over
SPEEDPLUS_DIST = [-0.22383016606510672, 0.5140979708255638, -0.0006649961199834066, -0.00021404771667484594,
                  -0.13124227429077406]  # fmt: skip
LABEL_FILES = {"train": "train.json", "val": "validation.json", "test": "test.json"}


def export(*args: str) -> tuple[int, list[str]]:
    result = CliRunner().invoke(main, ["export", *args, "--quiet"])
    return result.exit_code, [ln for ln in result.output.strip().splitlines() if ln]


def splits(root: Path) -> dict[str, list[int]]:
    return bop.read_json(root / "splits.json")["splits"]


def bop_truth(root: Path) -> dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """sample id -> (R, t in metres, K, cam_dist or zeros), read from the BOP scene files."""
    out = {}
    for split in splits(root):
        for scene in bop.scene_dirs(root, split):
            gt, cams = (bop.read_json(bop.scene_file(scene, n)) for n in ("scene_gt", "scene_camera"))
            for key, entries in gt.items():
                dist = np.asarray(cams[key].get("cam_dist", np.zeros(5)), np.float64)
                out[int(key)] = (*bop.gt_pose(entries[0]), bop.camera_K(cams[key]), dist)
    return out


def project(V: np.ndarray, R: np.ndarray, t: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    uv, _ = cv2.projectPoints(V, cv2.Rodrigues(R)[0], t, K, dist)
    return uv.reshape(-1, 2)


def check_speedplus(root: Path, out: Path, dist: np.ndarray) -> None:
    """The labels of every split hold the BOP poses in SPEED+'s convention, and the images are there."""
    cam = bop.read_json(out / "camera.json")
    truth = bop_truth(root)
    K = truth[0][2]
    assert np.array_equal(cam["cameraMatrix"], K) and np.array_equal(cam["distCoeffs"], dist)
    assert (cam["Nu"], cam["Nv"], cam["ccx"], cam["ccy"]) == (320, 240, K[0, 2], K[1, 2])
    # (f p) / p: a product and a quotient, within 2 u64 (2.2e-16) of f, where a focal length in metres not
    # over the pitch is off by 1e5 or more
    assert (cam["fx"] / cam["ppx"], cam["fy"] / cam["ppy"]) == pytest.approx((K[0, 0], K[1, 1]), rel=1e-15)
    V = np.asarray(bop.read_model_mesh(root, 1).vertices)
    names, transposed = [], []
    for split, ids in splits(root).items():
        labels = bop.read_json(out / "synthetic" / LABEL_FILES[split])
        assert [int(lab["filename"][3:9]) for lab in labels] == ids
        for lab, sid in zip(labels, ids, strict=True):
            transposed.append(check_label(root, out / "synthetic" / "images", cam, V, truth, lab, split, sid))
            names.append(lab["filename"])
    assert sorted(names) == sorted(p.name for p in (out / "synthetic" / "images").iterdir())
    assert max(transposed) > 10.0  # the check sees the classic bug, a transposed quaternion


def check_label(root: Path, images: Path, cam: dict, V: np.ndarray, truth: dict, lab: dict, split: str,
                sid: int) -> float:  # fmt: skip
    """One SPEED+ label holds sample `sid`'s BOP pose in SPEED+'s convention and its image is the rendered
    one; returns how far the transposed rotation's projection misses."""
    R, t, K, d = truth[sid]
    q, r = np.asarray(lab["q_vbs2tango_true"]), np.asarray(lab["r_Vo2To_vbs_true"])
    # SPEED+'s client maps body to camera by quat2dcm(q)ᵀ, quat2dcm being the passive DCM (camera to
    # body) of the scalar-first q: the transpose of the active rotation scipy builds from q
    A = Rotation.from_quat(q[[1, 2, 3, 0]]).as_matrix()
    expected = project(V, R, t, K, d)
    assert np.abs(project(V, A, r, K, np.asarray(cam["distCoeffs"])) - expected).max() < 1e-6
    image = images / lab["filename"]
    assert image.read_bytes() == Layout(root).rgb(split, sid, image.suffix[1:]).read_bytes()
    return float(np.abs(project(V, A.T, r, K, d) - expected).max())


def test_speedplus_poses_project_as_the_bop_poses(small_dataset: Path, tmp_path: Path):
    out = tmp_path / "speedplus"
    code, lines = export(str(small_dataset), "--format", "speedplus", "--out", str(out))
    assert code == 0 and len(lines) == 1, lines
    check_speedplus(small_dataset, out, np.zeros(5))  # no cam_dist: a pinhole camera
    assert sorted(p.name for p in out.iterdir()) == ["camera.json", "synthetic"]  # no trajectory files
    assert sorted(p.name for p in (out / "synthetic").iterdir()) == ["images", *sorted(LABEL_FILES.values())]


def test_a_sequence_exports_as_shirt_trajectories(sequence_dataset: Path, tmp_path: Path):
    """A sequence dataset is written as SHIRT lays out a trajectory: per sequence a folder with
    metadata.json and one time-ordered SPEED+ label file, the split as an index of trajectories; every
    label holds its frame's BOP pose in SPEED+'s convention."""
    out = tmp_path / "shirt"
    code, lines = export(str(sequence_dataset), "--format", "speedplus", "--out", str(out))
    assert code == 0 and len(lines) == 1 and "seq0000/synthetic/seq0000.json 4" in lines[0], lines
    frames, dt = SEQUENCE["frames"], SEQUENCE["dt_s"]
    index = bop.read_json(out / "trajectories.json")
    by_split = {s: sorted({i // frames for i in ids}) for s, ids in splits(sequence_dataset).items()}
    assert index == {Path(LABEL_FILES[s]).stem: [f"seq{k:04d}" for k in ks] for s, ks in by_split.items()}
    assert sorted(p.name for p in out.iterdir()) == ["camera.json", "seq0000", "seq0001", "seq0002",
                                                     "trajectories.json"]  # fmt: skip
    cam, truth = bop.read_json(out / "camera.json"), bop_truth(sequence_dataset)
    V = np.asarray(bop.read_model_mesh(sequence_dataset, 1).vertices)
    rows = {int(r["sample_id"]): r for r in read_metadata(sequence_dataset)}
    for split, seqs in by_split.items():
        for k in seqs:
            name = f"seq{k:04d}"
            meta = bop.read_json(out / name / "metadata.json")
            assert (meta["cam_step"], meta["num_images"], meta["sequence_id"]) == (dt, frames, k)
            assert (meta["r_pri2cam_pri"], meta["q_pri2cam"]) == ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0])
            assert meta["profile"] == rows[k * frames]["profile"]
            labels = bop.read_json(out / name / "synthetic" / f"{name}.json")
            ids = [k * frames + f for f in range(frames)]  # frame 0 first: time order
            assert [int(lab["filename"][3:9]) for lab in labels] == ids
            assert [float(rows[i]["time_s"]) for i in ids] == [f * dt for f in range(frames)]
            images = out / name / "synthetic" / "images"
            for lab, sid in zip(labels, ids, strict=True):
                check_label(sequence_dataset, images, cam, V, truth, lab, split, sid)
            assert sorted(p.name for p in images.iterdir()) == [lab["filename"] for lab in labels]


@pytest.fixture(scope="module")
def lens_dataset(small_dataset: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The small dataset with SPEED+'s lens written as every image's cam_dist (labels only: the pixels
    stay those of a pinhole render)."""
    root = tmp_path_factory.mktemp("lens") / "ds"
    shutil.copytree(small_dataset, root)
    for path in root.glob("*/[0-9]*/scene_camera.json"):
        cams = bop.read_json(path)
        path.write_text(json.dumps({k: {**v, "cam_dist": SPEEDPLUS_DIST} for k, v in cams.items()}))
    return root


@pytest.mark.parametrize("mode", ["hardlink", "symlink"])
def test_speedplus_carries_cam_dist_and_links_images(lens_dataset: Path, tmp_path: Path, mode: str):
    out = tmp_path / "speedplus"
    assert export(str(lens_dataset), "--format", "speedplus", "--out", str(out), "--images", mode)[0] == 0
    check_speedplus(lens_dataset, out, np.asarray(SPEEDPLUS_DIST))
    image = next((out / "synthetic" / "images").iterdir())
    assert image.is_symlink() == (mode == "symlink") and (mode == "symlink" or image.stat().st_nlink == 2)


def test_coco_masks_boxes_and_factors_read_back_with_pycocotools(small_dataset: Path, tmp_path: Path):
    out = tmp_path / "coco"
    assert export(str(small_dataset), "--format", "coco", "--out", str(out))[0] == 0
    layout = Layout(small_dataset)
    with open(layout.metadata_path, newline="") as f:
        rows = {int(r["sample_id"]): r for r in csv.DictReader(f)}
    n_masks = 0
    for split, ids in splits(small_dataset).items():
        path = out / f"instances_{split}.json"
        raw = bop.read_json(path)
        assert all(isinstance(a["segmentation"]["counts"], str) for a in raw["annotations"])
        coco = COCO(str(path))
        assert sorted(coco.getImgIds()) == sorted(ids) and coco.getCatIds() == [1]
        for sid in ids:
            img = coco.loadImgs(sid)[0]
            assert img["file_name"] == f"{split}/000000/rgb/{sid:06d}.jpg"  # the default camera: JPEG
            assert (small_dataset / img["file_name"]).is_file()
            assert {k: str(img[k]) for k in rows[sid]} == rows[sid]  # every factor, as extra fields
            visib = cv2.imread(str(layout.mask(split, sid, visib=True)), cv2.IMREAD_UNCHANGED) > 127
            anns = coco.loadAnns(coco.getAnnIds(imgIds=sid))
            assert len(anns) == int(visib.any())
            for ann in anns:
                decoded = coco.annToMask(ann).astype(bool)
                assert np.array_equal(decoded, visib)
                rle = ann["segmentation"]
                assert ann["area"] == visib.sum() == mask_utils.area(rle)
                assert ann["bbox"] == mask_utils.toBbox(rle).tolist() and ann["iscrowd"] == 0
                n_masks += 1
    assert n_masks >= 10
    # the ground truth scored as detections by COCO's own evaluation: a perfect score
    coco = COCO(str(out / "instances_train.json"))
    for kind in ("bbox", "segm"):
        dets = coco.loadRes([{**a, "score": 1.0} for a in coco.dataset["annotations"]])
        ev = COCOeval(coco, dets, kind)
        ev.evaluate(), ev.accumulate(), ev.summarize()
        # every detection a true positive at every IoU threshold (IoU exactly 1): pycocotools' precisions
        # tp / (tp + fp + 2^-52) with fp = 0 are 1 to a u64, so their mean too, where one box missed is O(1/n)
        assert ev.stats[0] == pytest.approx(1.0, rel=0, abs=1e-15)


def test_bad_input_is_one_line_and_writes_nothing(small_dataset: Path, tmp_path: Path):
    not_dataset = tmp_path / "photos"
    not_dataset.mkdir()
    (not_dataset / "a.png").write_bytes(b"")
    full = tmp_path / "full"
    full.mkdir()
    (full / "keep.txt").write_text("mine")
    out = tmp_path / "out"
    cases = [
        ([str(not_dataset), "--format", "coco", "--out", str(out)], str(not_dataset)),
        ([str(small_dataset), "--format", "yolo", "--out", str(out)], "'yolo'"),
        ([str(small_dataset), "--format", "coco", "--out", str(full)], f"{full} exists (give --overwrite"),
        ([str(small_dataset), "--format", "coco", "--out", str(small_dataset / "coco")], "overlaps"),
        ([str(small_dataset), "--format", "coco", "--out", str(out), "--images", "copy"], "speedplus only"),
        ([str(small_dataset), "--format", "speedplus", "--out", str(out), "--images", "move"], "'move'"),
    ]
    for args, message in cases:
        code, lines = export(*args)
        assert code != 0 and len(lines) == 1 and message in lines[0], (args, lines)
    assert not out.exists() and not (small_dataset / "coco").exists()
    assert [p.name for p in full.iterdir()] == ["keep.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["full", "photos"]  # no temporary left beside
    assert export(str(small_dataset), "--format", "coco", "--out", str(full), "--overwrite")[0] == 0
    assert sorted(p.name for p in full.iterdir()) == [f"instances_{s}.json" for s in ("test", "train", "val")]


def test_a_failure_while_writing_leaves_out_untouched(small_dataset: Path, tmp_path: Path):
    root = tmp_path / "ds"
    shutil.copytree(small_dataset, root)
    sid = splits(root)["test"][-1]
    Layout(root).mask("test", sid, visib=True).unlink()
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.json").write_text("{}")
    code, lines = export(str(root), "--format", "coco", "--out", str(out), "--overwrite")
    assert code != 0 and len(lines) == 1 and f"sample {sid}" in lines[0], lines
    assert [p.name for p in out.iterdir()] == ["old.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds", "out"]


@pytest.mark.parametrize("fmt", ["speedplus", "coco"])
def test_a_dataset_with_an_image_that_cannot_be_read_is_refused(
    small_dataset: Path, tmp_path: Path, fmt: str
) -> None:
    """Every image is decoded before anything is written: a truncated one is named in one line."""
    root = tmp_path / "ds"
    shutil.copytree(small_dataset, root)
    layout = Layout(root)
    record = next(layout.record_paths())
    rec = bop.read_json(record)
    image = layout.rgb(rec["split"], rec["sample_id"], bop.read_json(layout.manifest_path)["rgb_format"])
    image.write_bytes(image.read_bytes()[:100])
    code, lines = export(str(root), "--format", fmt, "--out", str(tmp_path / "out"))
    why = f"sample {rec['sample_id']}: cannot read {image}: truncated or not an image"
    assert code == 1 and lines == [f"Error: {why}"], lines
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]


def test_a_format_is_one_registry_entry(small_dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """The registry is the one list of formats: `--help` shows every entry's layout, and an entry added to it
    is a working `--format`, its writer handed the decoded dataset and a staging folder that becomes OUT."""
    help_text = CliRunner().invoke(main, ["export", "--help"]).output
    for fmt in FORMATS.values():
        assert f"{fmt.name}: {fmt.layout}" in help_text

    def write_ids(source: Source, out: Path) -> dict[str, int]:
        ids = {split: [s.sample_id for s in source.split(split)] for split in splits(small_dataset)}
        (out / "ids.json").write_text(json.dumps(ids))
        return {"ids.json": len(source.samples)}

    monkeypatch.setitem(
        FORMATS, "ids", ExportFormat("ids", "sample ids per split", "OUT/ids.json", write_ids)
    )
    code, lines = export(str(small_dataset), "--format", "ids", "--out", str(tmp_path / "ids"))
    assert code == 0, lines
    assert json.loads((tmp_path / "ids" / "ids.json").read_text()) == splits(small_dataset)
    code, lines = export(
        str(small_dataset), "--format", "ids", "--out", str(tmp_path / "x"), "--images", "copy"
    )
    assert code != 0 and "ids writes no images" in lines[0]
