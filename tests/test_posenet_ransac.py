"""PnP-RANSAC beside Patch-PnP: exact correspondences give the GT pose; `posenet eval --pnp both`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from posenet_helpers import tiny_pose_checkpoint

from posenet.cli import main
from posenet.config import smoke_config
from posenet.data import open_split
from posenet.evaluation.metrics import rotation_error_deg, translation_error
from posenet.models import ModelConfig
from posenet.predict.ransac import ransac_poses


def test_ground_truth_xyz_and_mask_give_the_ground_truth_pose(dataset_dir: Path) -> None:
    """The dataset's own xyz and visible-mask targets, fed as the network's outputs: PnP-RANSAC with the
    crop's pixel centres mapped to the image and the image's K recovers each GT pose."""
    cfg = smoke_config().data
    model_cfg = ModelConfig.create("gdrnet", "smoke", input_res=256, output_res=64)
    dataset = open_split(dataset_dir, "train", cfg, model_cfg, train=True)
    items = [dataset[(0, i)] for i in range(len(dataset))]
    items = [it for it in items if it["roi_mask_visib"].sum() >= 200]  # enough pixels for a sharp pose
    batch = {k: torch.stack([it[k] for it in items]) for k in items[0]}
    out = {"xyz": batch["roi_xyz"], "mask": batch["roi_mask_visib"] * 20 - 10}  # logits of the GT mask
    R, t, solved = ransac_poses(out, batch, dataset.obj.extent, "bce")
    assert len(items) >= 8 and bool(solved.all())
    distance = batch["t"].norm(dim=-1)
    assert float(rotation_error_deg(R.double(), batch["R"].double()).max()) < 2.0
    assert float((translation_error(t, batch["t"]) / distance).max()) < 0.02
    # the raw channel of an 'l1' mask head reads the same pixels as visible: the same correspondences into
    # the same solve (solvePnPRansac seeds its own generator), so the same floats
    R_l1, _, _ = ransac_poses({**out, "mask": batch["roi_mask_visib"]}, batch, dataset.obj.extent, "l1")
    assert torch.equal(R_l1, R)


def test_eval_pnp_both_sets_ransac_beside_patch(
    dataset_dir: Path, tmp_path_factory: pytest.TempPathFactory, tmp_path: Path
) -> None:
    ckpt = tiny_pose_checkpoint(dataset_dir, tmp_path_factory)
    out = tmp_path / "test.json"
    args = ["eval", "--data", dataset_dir, "--ckpt", ckpt, "--json", out, "--workers", 0, "--pnp", "both"]
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    header = res.stdout.splitlines()[1]  # the table under "boxes: ..."; the progress bar is on stderr
    assert "Patch-PnP" in header and "PnP-RANSAC" in header and "PnP failed" in res.output
    summary = json.loads(out.read_text())
    patch, ransac = summary["patch"], summary["ransac"]
    assert patch["n"] == ransac["n"] and patch["pnp"] == "Patch-PnP" and ransac["pnp"] == "PnP-RANSAC"
    assert 0 <= ransac["pnp_failed"] <= ransac["n"]
    rows = [json.loads(line) for line in out.with_suffix(".predictions.jsonl").read_text().splitlines()]
    assert [r["pnp"] for r in rows] == ["patch"] * patch["n"] + ["ransac"] * ransac["n"]
    failed = [r for r in rows if r.get("pnp_failed")]
    assert len(failed) == ransac["pnp_failed"] and all(r["R"] is None and r["re_deg"] is None for r in failed)
    groups = tmp_path / "groups.json"
    ids = sorted({r["im_id"] for r in rows})
    groups.write_text(json.dumps({"seed": 0, "n": len(ids), "groups": {"all": {"all": ids}}}))
    args = [
        "eval",
        "--data",
        dataset_dir,
        "--ckpt",
        ckpt,
        "--by-factor",
        groups,
        "--workers",
        0,
        "--pnp",
        "both",
    ]
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    assert "gdrnet PnP-RANSAC" in res.stdout.splitlines()[1]  # the progress bars are on stderr
    assert np.isfinite(patch["te_m"])
