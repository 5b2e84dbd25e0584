"""posenet on BOP datasets: symmetries (models_info) in the PM loss and the metrics, --obj-id on a dataset
with two objects, and the BOP19 results file of `posenet eval --bop-csv`."""

from __future__ import annotations

import csv
import json
import math
import shutil
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from posenet_helpers import posenet_dataset

from posenet.cli import main
from posenet.data.layout import scan_split
from posenet.data.object_model import load_object_model
from posenet.evaluation.evaluate import per_image_times
from posenet.evaluation.metrics import sample_errors, summarise
from posenet.geometry import rot6d_to_mat
from posenet.training.losses import PmObject, closest_symmetric_rotation, pm_loss
from scgen.io import bop

TINY = """\
preset: smoke
model: {input_res: 64, output_res: 16, head_channels: 32, pnp_channels: 32, fc_dims: [64, 32]}
data: {workers: 0}
optim: {batch_size: 4, epochs: 1}
"""
BOP_HEADER = "scene_id,im_id,obj_id,score,R,t,time"
# the objects of each image of the two-object set, by the image's position in its split (cycled):
# the index in the list is the instance's gt index, which names its mask and xyz files
PATTERNS = ([1], [2, 1], [2, 1, 2])
FLIP_Z_MM = [-1.0, 0, 0, 30.0, 0, -1.0, 0, -20.0, 0, 0, 1.0, 0, 0, 0, 0, 1.0]  # 180 deg about x=15, y=-10 mm


def rot_z(deg: float) -> torch.Tensor:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)


def random_rotations(n: int, seed: int) -> torch.Tensor:
    return rot6d_to_mat(torch.randn(n, 6, generator=torch.Generator().manual_seed(seed), dtype=torch.float64))


def posenet(*args: object) -> tuple[int, str]:
    res = CliRunner().invoke(main, [str(a) for a in args])
    return res.exit_code, res.output


# --- symmetries from models_info ------------------------------------------------------------------------


def test_models_info_symmetries_become_metric_transforms_with_the_identity_first() -> None:
    """The allclose/isclose checks: float64 mm / 1000 and unit rotations built from cos and sin, a few u64
    (1e-16) each, far inside numpy's defaults (rtol 1e-5, atol 1e-8), where a wrong transform is O(1)."""
    info = {"diameter": 100.0, "symmetries_discrete": [FLIP_Z_MM]}
    T = bop.symmetry_transforms(info)
    assert T.shape == (2, 4, 4) and np.array_equal(T[0], np.eye(4))
    assert np.allclose(T[1, :3, 3], [0.03, -0.02, 0.0])  # mm -> m; the rotation stays as given
    assert np.array_equal(T[1, :3, :3], np.diag([-1.0, -1.0, 1.0]))
    assert np.array_equal(bop.symmetry_transforms({"diameter": 1.0}), np.eye(4)[None])

    axis_point = np.array([0.01, 0.02, 0.0])  # metres; offset in models_info is mm
    cont = {"symmetries_continuous": [{"axis": [0, 0, 2.0], "offset": (axis_point * 1000).tolist()}]}
    turns = bop.symmetry_transforms(cont)  # BOP's max_sym_disc_step 0.01: ceil(pi / 0.01) turns
    assert turns.shape == (315, 4, 4) and np.allclose(turns[0], np.eye(4))
    for turn in turns[[1, 100, 314]]:
        R = turn[:3, :3]
        assert np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1)
        assert np.allclose(R @ axis_point + turn[:3, 3], axis_point)  # points on the axis stay put
    step = np.degrees(np.arccos(turns[1, 0, 0]))
    assert step == pytest.approx(360 / 315)
    both = bop.symmetry_transforms({**info, **cont})  # every turn after each discrete symmetry
    assert both.shape == (630, 4, 4)
    assert np.allclose(both[315 + 7], turns[7] @ T[1]) and np.allclose(both[7], turns[7])


# --- the PM loss ----------------------------------------------------------------------------------------


def test_pm_loss_is_the_minimum_over_the_symmetric_poses_of_the_gt() -> None:
    """float64 throughout: a symmetric pose's loss is a few u64 x |p| (<= 0.87), under 1e-15, hence 1e-12; the
    same minimum taken two ways agrees to a few u64 relative, inside rel=1e-12."""
    pts = torch.rand(400, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64) - 0.5
    R_gt, t_gt = (
        random_rotations(4, seed=2),
        torch.tensor([[0.0, 0.0, 2.0]], dtype=torch.float64).expand(4, 3),
    )
    flip = torch.from_numpy(bop.symmetry_transforms({"symmetries_discrete": [FLIP_Z_MM]}))
    symmetric, plain = PmObject(pts, flip), PmObject(pts, flip[:1])

    R_flipped = R_gt @ flip[1, :3, :3]
    assert float(pm_loss(R_flipped, R_gt, pts)) > 0.5  # far from the GT itself ...
    target = closest_symmetric_rotation(R_flipped, R_gt, t_gt, symmetric)
    assert float(pm_loss(R_flipped, target, pts)) < 1e-12  # ... but a symmetric pose of it

    R_pred = random_rotations(4, seed=3)
    target = closest_symmetric_rotation(R_pred, R_gt, t_gt, symmetric)
    per_sample = [
        min(float(pm_loss(R_pred[i], R_gt[i] @ S[:3, :3], pts)) for S in flip) for i in range(len(R_pred))
    ]
    assert float(pm_loss(R_pred, target, pts)) == pytest.approx(np.mean(per_sample), rel=1e-12)
    assert closest_symmetric_rotation(R_pred, R_gt, t_gt, plain) is R_gt  # no symmetry: the plain loss

    turns = torch.from_numpy(
        bop.symmetry_transforms({"symmetries_continuous": [{"axis": [0, 0, 1], "offset": [0, 0, 0]}]})
    )
    R_turned = R_gt @ rot_z(40 * 360 / 315)  # the 40th discrete turn
    target = closest_symmetric_rotation(R_turned, R_gt, t_gt, PmObject(pts, turns), max_block=5000)
    assert float(pm_loss(R_turned, target, pts)) < 1e-12


# --- ADD-S, MSSD and the symmetric rotation error ------------------------------------------------------


def test_a_flip_scores_zero_for_an_object_declared_symmetric_only() -> None:
    """A 180 deg turn about an axis the point set is symmetric about (not through the origin)."""
    half = torch.rand(300, 3, generator=torch.Generator().manual_seed(4), dtype=torch.float64) * 0.1
    flip = torch.from_numpy(bop.symmetry_transforms({"symmetries_discrete": [FLIP_Z_MM]}))
    pts = torch.cat([half, half @ flip[1, :3, :3].T + flip[1, :3, 3]])  # symmetric about the axis
    R_gt, t_gt = (
        random_rotations(3, seed=5),
        torch.tensor([[0.1, -0.2, 3.0]], dtype=torch.float64).expand(3, 3),
    )
    # the prediction shows the model moved by the symmetry: X_cam = R_gt (S X) + t_gt
    R_pred, t_pred = R_gt @ flip[1, :3, :3], (R_gt @ flip[1, :3, 3]) + t_gt

    sym = sample_errors(R_pred, t_pred, R_gt, t_gt, pts, pts, flip)
    asym = sample_errors(R_pred, t_pred, R_gt, t_gt, pts, pts, flip[:1])
    for errs in (sym, asym):
        # arccos near -1 turns a few u64 into sqrt(8 u64) rad = 1.7e-6 deg, inside allclose's 1e-5 x 180
        assert torch.allclose(errs["re_deg"], torch.full((3,), 180.0, dtype=torch.float64))
        # ADD-S never asks: the point sets coincide (cdist's |a|^2 + |b|^2 - 2 a.b: sqrt(8 u64) |a| = 9e-8)
        assert float(errs["adds_m"].max()) < 1e-6
        assert float(errs["add_m"].min()) > 0.01
    # arccos near 1: sqrt(8 u64) rad = 1.7e-6 deg; MSSD a few u64 x 3 m, 1e-15
    assert float(sym["re_sym_deg"].max()) < 1e-5 and float(sym["mssd_m"].max()) < 1e-12
    assert torch.equal(asym["re_sym_deg"], asym["re_deg"])
    moved = (pts @ flip[1, :3, :3].T + flip[1, :3, 3] - pts).norm(dim=-1).max()  # rigid: frame-independent
    assert torch.allclose(asym["mssd_m"], moved.expand(3))

    diameter = 0.2
    s_sym = summarise({k: v.tolist() for k, v in sym.items()}, diameter, symmetric=True)
    s_asym = summarise({k: v.tolist() for k, v in asym.items()}, diameter, symmetric=False)
    assert (s_sym["add_metric"], s_asym["add_metric"]) == ("ADD-S", "ADD")
    assert s_sym["add_0.1d"] == s_sym["mssd_0.1d"] == s_sym["ar_mssd"] == 1.0
    assert s_asym["add_0.1d"] == s_asym["mssd_0.1d"] == 0.0 and s_asym["adds_0.1d"] == 1.0
    expected_ar = np.mean([float(moved) < f * diameter for f in np.arange(1, 11) * 0.05])
    # recalls of 0 or 1 (MSSD 0.26 m lies 0.16 m past the last threshold) averaged: k / 10 both ways
    assert s_asym["ar_mssd"] == expected_ar


# --- the BOP19 results file -----------------------------------------------------------------------------


def parse_bop_csv(path: Path) -> tuple[list[str], list[dict]]:
    """The header and rows of a BOP19 results file, read as bop_toolkit's load_bop_results reads it."""
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    out = []
    for row in rows[1:]:
        assert len(row) == 7, row
        R, t = [float(v) for v in row[4].split(" ")], [float(v) for v in row[5].split(" ")]
        assert len(R) == 9 and len(t) == 3, row
        keys = ("scene_id", "im_id", "obj_id")
        out.append(
            {
                **dict(zip(keys, map(int, row[:3]), strict=True)),
                "score": float(row[3]),
                "R": R,
                "t_mm": t,
                "time": float(row[6]),
            }
        )
    return rows[0], out


def test_bop_csv_times_are_per_image_and_poses_round_trip(tmp_path: Path) -> None:
    R = random_rotations(3, seed=6).flatten(1).tolist()
    records = [
        {"scene_id": 0, "im_id": 4, "obj_id": 2, "R": R[0], "t": [0.1, -0.2, 2.5], "time_s": 0.01},
        {"scene_id": 0, "im_id": 4, "obj_id": 2, "R": R[1], "t": [-0.1, 0.0, 3.0], "time_s": 0.03},
        {"scene_id": 1, "im_id": 1004, "obj_id": 2, "R": R[2], "t": [0.0, 0.05, 1.0], "time_s": 0.02},
    ]
    records = per_image_times(records)
    assert [r["time_s"] for r in records] == [0.04, 0.04, 0.02]  # 0.0 + 0.01 + 0.03 rounds to 0.04's float
    path = tmp_path / "posenet_scgen-test.csv"
    path.write_text(bop.results_csv(records))
    header, rows = parse_bop_csv(path)
    assert ",".join(header) == BOP_HEADER and len(rows) == 3
    for r, row in zip(records, rows, strict=True):
        assert (row["scene_id"], row["im_id"], row["obj_id"]) == (r["scene_id"], r["im_id"], 2)
        assert row["score"] == 1.0 and row["R"] == r["R"] and row["time"] == r["time_s"]
        assert row["t_mm"] == pytest.approx([1000 * v for v in r["t"]], rel=1e-12)  # x 1000: one u64 rounding


# --- --obj-id on a dataset with two objects ---------------------------------------------------------------


@pytest.fixture(scope="module")
def two_objects(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The rendered set relabelled into a BOP folder with objects 1 and 2 (2: the same mesh, declared
    symmetric): each image holds the instances of its PATTERNS entry, every one a copy of the target."""
    root = tmp_path_factory.mktemp("bop2") / "ds"
    shutil.copytree(posenet_dataset(tmp_path_factory), root)
    models = root / bop.MODELS_DIR
    shutil.copy(models / bop.model_file(1), models / bop.model_file(2))
    info = bop.read_models_info(root)
    info["2"] = {**info["1"], "symmetries_discrete": [FLIP_Z_MM]}
    (models / bop.MODELS_INFO_FILE).write_text(json.dumps(info))
    for scene in sorted(root.glob("*/[0-9]*")):
        gt, cams, infos = (bop.read_json(bop.scene_file(scene, n)) for n in bop.SCENE_FILES)
        for pos, im in enumerate(sorted(gt, key=int)):
            pattern = PATTERNS[pos % len(PATTERNS)]
            gt[im] = [{**gt[im][0], "obj_id": o} for o in pattern]
            infos[im] = infos[im] * len(pattern)
            for j in range(1, len(pattern)):
                for src in (bop.mask_path(scene, int(im), 0), bop.mask_path(scene, int(im), 0, visib=True),
                            bop.xyz_path(scene, int(im), 0)):  # fmt: skip
                    if src.is_file():
                        shutil.copy(src, src.with_name(src.name.replace("_000000.", f"_{j:06d}.")))
        for name, content in zip(bop.SCENE_FILES, (gt, cams, infos), strict=True):
            bop.scene_file(scene, name).write_text(json.dumps(content))
    return root


def test_scan_selects_each_objects_instances_by_their_gt_index(two_objects: Path) -> None:
    gt = {}  # im_id: the obj_id of each instance, in scene_gt order
    for scene in sorted((two_objects / "test").glob("[0-9]*")):
        anns = bop.read_json(bop.scene_file(scene, "scene_gt"))
        gt |= {int(im): [a["obj_id"] for a in image] for im, image in anns.items()}
    assert max(Counter(objs)[2] for objs in gt.values()) == 2  # some image holds object 2 twice
    for obj_id in (1, 2):
        instances = scan_split(two_objects, "test", obj_id)
        want = sorted((im, j) for im, objs in gt.items() for j, o in enumerate(objs) if o == obj_id)
        assert sorted((i.im_id, i.inst) for i in instances) == want and want
        for i in instances:
            assert i.obj_id == obj_id and i.mask.is_file()
            assert i.mask.name == i.mask_visib.name == f"{i.im_id:06d}_{i.inst:06d}.png"
    assert len(load_object_model(two_objects, 2, num_regions=4, num_pm=100).symmetries) == 2
    assert len(load_object_model(two_objects, 1, num_regions=4, num_pm=100).symmetries) == 1


def test_obj_id_trains_evaluates_and_boxes_the_chosen_object(two_objects: Path, tmp_path: Path) -> None:
    for obj_id in (1, 2):
        boxes = tmp_path / f"boxes{obj_id}.json"
        assert posenet("boxes", "--data", two_objects, "--out", boxes, "--obj-id", obj_id)[0] == 0
        visible = [i for i in scan_split(two_objects, "test", obj_id) if i.px_count_visib > 0]
        entries = json.loads(boxes.read_text())
        assert {e["category_id"] for e in entries} == {obj_id} and len(entries) == len(visible)

    (tmp_path / "tiny.yaml").write_text(TINY)
    run = tmp_path / "run"
    args = ("train", "--data", two_objects, "--out", run, "--config", tmp_path / "tiny.yaml")
    code, out = posenet(*args, "--obj-id", 2, "--max-steps", 2)
    assert code == 0, out
    assert torch.load(run / "last.pt", weights_only=True)["config"]["data"]["obj_id"] == 2
    code, out = posenet("train", "--data", two_objects, "--out", run, "--resume", "--obj-id", 1)
    assert code == 1 and "trains object 2, not object 1" in out

    pred, summary, results = (tmp_path / n for n in ("pred.jsonl", "test.json", "posenet_scgen-test.csv"))
    code, out = posenet(
        "eval", "--data", two_objects, "--ckpt", run / "last.pt", "--json", summary, "--predictions", pred,
        "--bop-csv", results, "--workers", 0, "--batch-size", 2,
    )  # fmt: skip
    assert code == 0, out
    s = json.loads(summary.read_text())
    assert s["symmetric"] is True and s["add_metric"] == "ADD-S" and "ADD-S@0.02m (%)" in out
    assert s["add_0.1d"] == s["adds_0.1d"] and {"re_sym_deg", "mssd_0.1d", "ar_mssd"} <= set(s)
    records = [json.loads(line) for line in pred.read_text().splitlines()]
    visible = [i for i in scan_split(two_objects, "test", 2) if i.px_count_visib > 0]
    assert [(r["im_id"], r["obj_id"]) for r in records] == [(i.im_id, 2) for i in visible]
    assert all(r["re_sym_deg"] <= r["re_deg"] + 1e-9 and r["mssd_m"] > 0 for r in records)

    header, rows = parse_bop_csv(results)
    assert ",".join(header) == BOP_HEADER and len(rows) == len(records)
    times: dict[tuple[int, int], set[float]] = {}
    for r, row in zip(records, rows, strict=True):
        assert (row["scene_id"], row["im_id"], row["obj_id"]) == (r["scene_id"], r["im_id"], 2)
        # the CSV holds R as given and t x 1000 (one float64 rounding, 1e-16 relative)
        assert row["R"] == r["R"] and row["t_mm"] == pytest.approx([1000 * v for v in r["t"]], rel=1e-12)
        times.setdefault((row["scene_id"], row["im_id"]), set()).add(row["time"])
    assert all(len(t) == 1 and next(iter(t)) > 0 for t in times.values())  # one time per image
    assert max(Counter(r["im_id"] for r in records).values()) == 2  # ... also for two estimates
