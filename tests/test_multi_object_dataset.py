"""The dataset tools on a real Mitsuba render with several labelled objects per image
(examples/servicer_client.toml): `scgen validate` checks every instance against its own model, `scgen stats`
counts every object, the COCO export holds every visible instance (read back with pycocotools), and the
SPEED+ export writes the one object asked for."""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO
from scipy.spatial.transform import Rotation

from scgen.cli import main
from scgen.dataset.layout import Layout, object_names, open_dataset
from scgen.dataset.stats import compute_stats, format_table, to_csv
from scgen.dataset.validate import validate_dataset
from scgen.io import bop
from scgen.scenes.factors import FACTOR_GROUPS
from tests.conftest import render_dataset

N = 6
CONFIG = Path(__file__).resolve().parents[1] / "examples" / "servicer_client.toml"


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return render_dataset(tmp_path_factory.mktemp("objects") / "ds", n=N, seed=3, config_path=CONFIG)


def instance_counts() -> dict[int, int]:
    """obj_id -> instances per image the config asks for: the target once, each [[objects]] entry `count`
    times, obj_ids in entry order from 2."""
    entries = tomllib.loads(CONFIG.read_text())["objects"]
    return {1: 1, **{k: int(e.get("count", 1)) for k, e in enumerate(entries, start=2)}}


def records(root: Path) -> list[dict]:
    return [bop.read_json(p) for p in Layout(root).record_paths()]


def export(*args: str) -> tuple[int, list[str]]:
    result = CliRunner().invoke(main, ["export", *args, "--quiet"])
    return result.exit_code, [ln for ln in result.output.strip().splitlines() if ln]


def visible(rec: dict) -> list[int]:
    """The scene_gt indices of a record's instances with visible pixels."""
    return [k for k, info in enumerate(rec["scene_gt_info"]) if info["px_count_visib"] > 0]


def test_every_image_holds_every_configured_instance(dataset: Path):
    counts = instance_counts()
    for rec in records(dataset):
        obj_ids = [e["obj_id"] for e in rec["scene_gt"]]
        assert {k: obj_ids.count(k) for k in counts} == counts and obj_ids[0] == 1
    assert any(len(visible(rec)) > 1 for rec in records(dataset))  # the checks below see several masks


def test_validate_checks_every_instance_against_its_own_model(dataset: Path, tmp_path: Path):
    assert validate_dataset(dataset, progress=False) == ([], N)
    bad = tmp_path / "bad"
    shutil.copytree(dataset, bad)
    layout = Layout(bad)
    shutil.copy(bad / "models" / "obj_000002.ply", bad / "models_eval" / "obj_000002.ply")  # coarse CAD
    hit = [rec for rec in records(bad) if len(visible(rec)) > 1]
    assert len(hit) >= 2
    one, two = hit[0], hit[-1]
    a, (b, c) = visible(one)[-1], visible(two)[:2]  # a, c > 0: not the target
    # one sample: a non-target instance's visible mask truncated, its xyz map garbage
    sid, split = one["sample_id"], one["split"]
    unreadable = layout.mask(split, sid, visib=True, inst=a)
    unreadable.write_bytes(unreadable.read_bytes()[:40])
    layout.xyz(split, sid, inst=a).write_bytes(b"not an exr")
    # another: instance c's visible mask drawn over instance b's as well
    sid2, split2 = two["sample_id"], two["split"]
    paths = [layout.mask(split2, sid2, visib=True, inst=k) for k in (b, c)]
    over = np.maximum(*(cv2.imread(str(p), cv2.IMREAD_UNCHANGED) for p in paths))
    cv2.imwrite(str(paths[1]), over)
    problems, n = validate_dataset(bad, progress=False)
    assert n == N
    text = "\n".join(problems)
    obj_a, obj_c = one["scene_gt"][a]["obj_id"], two["scene_gt"][c]["obj_id"]
    assert f"sample {sid}: instance {a} (obj_id {obj_a}): cannot read {unreadable}" in text
    overlap = int(two["scene_gt_info"][b]["px_count_visib"])  # all of b's pixels, now c's too
    assert f"sample {sid2}: visible masks of different instances overlap at {overlap} pixels" in problems
    assert f"sample {sid2}: instance {c} (obj_id {obj_c}): px_count_visib" in text
    assert "models_eval has an edge of" in text and "obj_000002.ply" in text
    assert not any(f"sample {sid}: instance 0 " in p or f"sample {sid2}: instance 0 " in p for p in problems)


def test_stats_count_every_object_from_the_bop_files(dataset: Path, small_dataset: Path):
    stats = compute_stats(dataset, min_group=1)
    names = object_names(open_dataset(dataset)[1])
    counts = instance_counts()
    rows = [line.split()[:5] for line in format_table(stats).split("objects (")[1].splitlines()]
    for split, st in stats["splits"].items():
        assert list(st["objects"]) == [str(k) for k in counts]
        for obj_id, o in st["objects"].items():
            assert (o["name"], o["images"]) == (names[int(obj_id)], st["n"])
            assert o["instances"] == counts[int(obj_id)] * st["n"] == sum(o["occlusion"].values())
            q = list(o["visib_fract_quantiles"].values())
            assert q[0] >= 0.0 and q == sorted(q) and q[-1] <= 1.0
            assert [split, obj_id, o["name"], str(o["instances"]), str(o["images"])] in rows
        occlusion_rows = [r for r in to_csv(stats).splitlines() if r.startswith(f"{split},occlusion:")]
        assert len(occlusion_rows) == len(FACTOR_GROUPS["occlusion"]) * len(counts)
    one = compute_stats(small_dataset)
    assert all("objects" not in st for st in one["splits"].values())
    assert "objects (" not in format_table(one) and "occlusion:" not in to_csv(one)


def test_coco_holds_a_category_per_object_and_every_visible_instance(dataset: Path, tmp_path: Path):
    out = tmp_path / "coco"
    assert export(str(dataset), "--format", "coco", "--out", str(out))[0] == 0
    layout, names = Layout(dataset), object_names(open_dataset(dataset)[1])
    by_id = {rec["sample_id"]: rec for rec in records(dataset)}
    ann_ids = []
    for split in ("train", "val", "test"):
        coco = COCO(str(out / f"instances_{split}.json"))
        assert {c["id"]: c["name"] for c in coco.loadCats(coco.getCatIds())} == names
        for sid in coco.getImgIds():
            rec = by_id[sid]
            anns = coco.loadAnns(coco.getAnnIds(imgIds=sid))
            assert len(anns) == len(visible(rec))
            for ann, k in zip(anns, visible(rec), strict=True):
                assert ann["category_id"] == rec["scene_gt"][k]["obj_id"] and ann["iscrowd"] == 0
                png = cv2.imread(str(layout.mask(split, sid, visib=True, inst=k)), cv2.IMREAD_UNCHANGED) > 127
                assert np.array_equal(coco.annToMask(ann).astype(bool), png)
                assert ann["area"] == png.sum() == mask_utils.area(ann["segmentation"])
                assert ann["bbox"] == mask_utils.toBbox(ann["segmentation"]).tolist()
            ann_ids += [a["id"] for a in anns]
    assert len(ann_ids) == len(set(ann_ids)) == sum(len(visible(r)) for r in by_id.values())


def test_speedplus_writes_the_object_asked_for(dataset: Path, tmp_path: Path):
    out = tmp_path / "speedplus"
    names = object_names(open_dataset(dataset)[1])
    held = ", ".join(f"{k} ({name})" for k, name in names.items())
    refused = [
        ([], f"holds obj_ids {held}"),
        (["--obj-id", "3"], "2 instances of obj_id 3"),  # upper_stage: count 2 in the config
        (["--obj-id", "9"], "--obj-id 9 is not an object"),
    ]
    for extra, message in refused:
        code, lines = export(str(dataset), "--format", "speedplus", "--out", str(out), *extra)
        assert code != 0 and len(lines) == 1 and message in lines[0], (extra, lines)
    code, lines = export(str(dataset), "--format", "coco", "--out", str(out), "--obj-id", "2")
    assert code != 0 and "--obj-id applies to --format speedplus only" in lines[0]
    assert list(tmp_path.iterdir()) == []  # nothing written, no temporary left
    assert export(str(dataset), "--format", "speedplus", "--out", str(out), "--obj-id", "2")[0] == 0
    labels = {}
    for name in ("train.json", "validation.json", "test.json"):
        labels |= {int(lab["filename"][3:9]): lab for lab in bop.read_json(out / "synthetic" / name)}
    recs = records(dataset)
    assert sorted(labels) == sorted(r["sample_id"] for r in recs)
    for rec in recs:
        R, t = bop.gt_pose(rec["scene_gt"][1])  # smallsat: obj_id 2, the first [[objects]] entry
        lab = labels[rec["sample_id"]]
        q = np.asarray(lab["q_vbs2tango_true"])
        # float64 round trips: a rotation matrix through a quaternion and back, t copied
        assert np.abs(Rotation.from_quat(q[[1, 2, 3, 0]]).as_matrix() - R).max() < 1e-12
        assert lab["r_Vo2To_vbs_true"] == t.tolist()
