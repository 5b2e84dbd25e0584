"""`posenet eval` end to end on a briefly trained checkpoint: summary keys, predictions, by-factor table."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from click.testing import CliRunner
from float_bounds import gram_schmidt_gain, pose_checkpoint_rel, rotation_outputs

from posenet.cli import main
from posenet.evaluation.evaluate import SUMMARY_FIGURES, evaluate, format_table, summary_rows
from scgen.cli import main as scgen_main

METRIC_KEYS = ("te_m", "add_m", "add_rot_m", "adds_m", "mssd_m")  # metres: |dR| diameter + |dt| each


def rotation_error_bound_deg(re_deg: float, rel: float) -> float:
    """How far the rotation error can move when every entry of R moves by `rel`: cos(angle) =
    (tr(R_gt^T R) - 1) / 2 moves by at most d = 3 sqrt(3) rel / 2 (three unit-column dot products),
    so the angle by d / sin(angle), or sqrt(2 d) where arccos is steep near 0 and 180 deg."""
    d = 3 * math.sqrt(3) * rel / 2
    return math.degrees(max(min(d / max(math.sin(math.radians(re_deg)), 1e-300), math.pi), math.sqrt(2 * d)))


def assert_records_agree(a: dict, b: dict, diameter: float, rel: float, gain: float) -> None:
    """Record b equals record a within the forward's rounding: `rel` (float_bounds: another batch size is
    another GEMM blocking) of each output's scale, through the decode: R's unit entries by `gain` times it
    (gram_schmidt_gain), t by rel of its norm, the metric errors by both over the object's reach
    gain x diameter + |t|, each key in its own unit."""
    reach = math.hypot(*a["t"]) + gain * diameter
    assert b["R"] == pytest.approx(a["R"], abs=gain * rel), "R"
    assert b["t"] == pytest.approx(a["t"], abs=rel * math.hypot(*a["t"])), "t"
    assert b["tz_rel"] == pytest.approx(a["tz_rel"], abs=2 * rel), "tz_rel"  # a ratio: both ends move
    for key in ("re_deg", "re_sym_deg"):
        assert b[key] == pytest.approx(a[key], abs=rotation_error_bound_deg(a[key], gain * rel)), key
    for key in METRIC_KEYS:
        assert b[key] == pytest.approx(a[key], abs=2 * rel * reach), key
    # ESA: the rotation error in radians plus te / |t_gt| (|t_gt| >= |t| - te), each term zeroed under its
    # threshold (no 2-step pose sits within these bounds of one)
    t_gt_norm = max(math.hypot(*a["t"]) - a["te_m"], 1e-9)
    esa_bound = math.radians(rotation_error_bound_deg(a["re_deg"], gain * rel)) + 2 * rel * reach / t_gt_norm
    assert b["esa"] == pytest.approx(a["esa"], abs=esa_bound), "esa"


def test_eval_writes_summary_and_predictions(dataset_dir: Path, pose_ckpt: Path, tmp_path: Path) -> None:
    boxes = tmp_path / "boxes.json"
    assert CliRunner().invoke(main, ["boxes", "--data", str(dataset_dir), "--out", str(boxes)]).exit_code == 0
    out = tmp_path / "test.json"
    args = [
        "eval",
        "--data",
        dataset_dir,
        "--ckpt",
        pose_ckpt,
        "--boxes",
        boxes,
        "--json",
        out,
        "--workers",
        0,
    ]
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    assert "ADD@0.02m (%)" in res.output and "latency, batch 1 (ms)" in res.output
    assert "of the rotation alone" in res.output and "of the translation alone" in res.output
    assert "rotation error, median (deg)" in res.output and "turned poses" in res.output
    summary = json.loads(out.read_text())
    for key in ("re_deg", "te_m", "add_0.02m", "add_0.1d", "adds_0.1d", "esa", "latency_ms"):
        assert isinstance(summary[key], float), key
    for key in ("add_0.02m", "add_0.1d", "adds_0.1d"):
        assert 0.0 <= summary[key] <= 1.0
    assert summary["variant"] == "gdrnet" and summary["split"] == "test"
    rows = [json.loads(line) for line in out.with_suffix(".predictions.jsonl").read_text().splitlines()]
    assert len(rows) == summary["n"] == len(json.loads(boxes.read_text()))
    assert {"scene_id", "im_id", "R", "t", "re_deg", "te_m", "add_m", "adds_m", "esa"} <= set(rows[0])
    assert len(rows[0]["R"]) == 9 and len(rows[0]["t"]) == 3


def test_batched_evaluation_gives_the_batch_1_records(dataset_dir: Path, pose_ckpt: Path) -> None:
    with rotation_outputs() as rot6d:
        one = evaluate(dataset_dir, pose_ckpt, workers=0, batch_size=1)
    batched = evaluate(dataset_dir, pose_ckpt, workers=0, batch_size=3)
    assert len(one.records) > 3 and len(one.records) % 3  # several batches, the last one partial
    assert [list(r) for r in batched.records] == [list(r) for r in one.records]  # same keys, same order
    # one forward of one RoI per record, then the latency's (evaluate times the network after the split)
    gain = max(gram_schmidt_gain(d6[0]) for d6 in rot6d[: len(one.records)])
    rel = pose_checkpoint_rel(pose_ckpt)
    for a, b in zip(one.records, batched.records, strict=True):
        assert (a["scene_id"], a["im_id"]) == (b["scene_id"], b["im_id"])
        assert_records_agree(a, b, one.diameter, rel, gain)
    s1, sb = one.summary, batched.summary
    assert sb.keys() == s1.keys() and sb["fps"] == 1000 / sb["latency_ms"]
    # the summary's means and medians move no more than the records they are taken of; recalls and counts
    # are equal unless a record sits on a threshold within its bound (none does at these 2-step poses)
    worst = {k: max(abs(x[k] - y[k]) for x, y in zip(one.records, batched.records, strict=True))
             for k in ("re_deg", "re_sym_deg", "te_m", "tz_rel", *METRIC_KEYS, "esa")}  # fmt: skip
    for key in s1.keys() - {"latency_ms", "fps"}:
        base = key.removesuffix("_median")
        # + 1e-12: a float64 mean or median of the same records rounds by a few u64 of figures under ~1e3
        assert sb[key] == pytest.approx(s1[key], abs=worst.get(base, 0.0) + 1e-12), key


def test_group_summaries_and_summary_rows(dataset_dir: Path, pose_ckpt: Path) -> None:
    result = evaluate(dataset_dir, pose_ckpt, workers=0)
    ids = [r["im_id"] for r in result.records]
    whole = result.summary_of(set(ids))
    assert whole == {k: result.summary[k] for k in whole}  # every image: the split's own summary
    part = result.summary_of(set(ids[:2]))
    assert part["n"] == 2 and part["re_deg"] == pytest.approx(
        (result.errors["re_deg"][0] + result.errors["re_deg"][1]) / 2
    )
    # every figure the tables print is a key of the summary, under one label of its own
    assert {key for _, key, _ in SUMMARY_FIGURES} <= set(result.summary)
    assert len({label for label, _, _ in SUMMARY_FIGURES}) == len(SUMMARY_FIGURES)
    rows = summary_rows([result.summary, {**part, "turned": float("nan")}], ("n", "turned", "add_0.02m"))
    assert [r[0] for r in rows] == [
        "instances",
        "turned poses, rotation error > 135 deg (%)",
        "ADD@0.02m (%)",
    ]
    assert rows[0][1:] == [str(len(ids)), "2"] and rows[1][2] == "-"
    assert rows[2][1] == f"{100 * result.summary['add_0.02m']:.2f}"


def test_by_factor_table_averages_checkpoints_of_one_variant(
    dataset_dir: Path, pose_ckpt: Path, tmp_path: Path
) -> None:
    groups = tmp_path / "groups.json"
    args = ["stats", str(dataset_dir), "--sample-groups", "3", "--groups-out", str(groups)]
    res = CliRunner().invoke(scgen_main, args)
    assert res.exit_code == 0, res.output
    out = tmp_path / "factors.json"
    args = ["eval", "--data", dataset_dir, "--ckpt", pose_ckpt, "--ckpt", pose_ckpt, "--by-factor", groups]
    res = CliRunner().invoke(main, [str(a) for a in [*args, "--json", out, "--workers", 0]])
    assert res.exit_code == 0, res.output
    table = json.loads(out.read_text())
    assert table["columns"] == ["gdrnet"] and table["runs"] == {"gdrnet": 2}
    assert set(table["groups"]) == set(json.loads(groups.read_text())["groups"])
    assert "illumination/" in res.output
    res = CliRunner().invoke(
        main, [str(a) for a in ["eval", "--data", dataset_dir, "--ckpt", pose_ckpt, "--ckpt", pose_ckpt]]
    )
    assert res.exit_code == 1 and "only compared with --by-factor" in res.output


def test_format_table_aligns_columns() -> None:
    text = format_table(["metric", "value"], [["a", "1.0"], ["longer name", "22.50"]])
    lines = text.splitlines()
    assert len({len(line) for line in lines}) == 1 and lines[1].startswith("---")
