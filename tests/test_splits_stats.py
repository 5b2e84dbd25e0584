"""Factor-combination splits (no leakage, ratios) and `scgen stats` on a rendered dataset."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from scgen.cli import main
from scgen.dataset.layout import read_metadata
from scgen.dataset.splits import leakage, plan_splits
from scgen.generator import Generator
from scgen.io.bop import read_json
from scgen.scenes import load_config
from scgen.scenes.factors import FACTOR_GROUPS, combination_key, spec_key, viewpoint_cell, viewpoint_cells
from scgen.scenes.geometry import quat_to_matrix


@pytest.fixture(scope="module")
def keys_1000(spacecraft) -> list[str]:
    generator = Generator(spacecraft, load_config(), 5)
    return [spec_key(generator.scene(i)) for i in range(1000)]


def test_factor_split_has_no_leakage_and_ratios_within_2pp(keys_1000):
    split_of = plan_splits(keys_1000, (0.7, 0.1, 0.2), seed=5, mode="factors")
    assert leakage(keys_1000, split_of) == {"train-val": 0, "train-test": 0, "val-test": 0}
    for name, ratio in zip(("train", "val", "test"), (0.7, 0.1, 0.2), strict=True):
        assert abs(split_of.count(name) / 1000 - ratio) <= 0.02
    random_split = plan_splits(keys_1000, (0.7, 0.1, 0.2), seed=5, mode="random")
    print("leakage factors:", leakage(keys_1000, split_of), "random:", leakage(keys_1000, random_split))
    assert sum(leakage(keys_1000, random_split).values()) > 0  # the image-level baseline leaks
    assert plan_splits(keys_1000, (0.7, 0.1, 0.2), seed=5) == split_of


def test_viewpoint_cells_partition_the_sphere():
    cells = viewpoint_cells()
    assert cells.shape == (20, 3)
    rng = np.random.default_rng(0)
    dirs = rng.normal(size=(20000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    counts = np.bincount(np.argmax(dirs @ cells.T, axis=1), minlength=20)
    assert counts.min() > 0.8 * 1000 and counts.max() < 1.2 * 1000  # equal-area faces


def test_keys_rederived_from_metadata_never_cross_splits(small_dataset: Path):
    rows = read_metadata(small_dataset)
    splits = read_json(small_dataset / "splits.json")
    split_of_key: dict[str, str] = {}
    for r in rows:
        R = quat_to_matrix(np.array([float(r[k]) for k in ("qw", "qx", "qy", "qz")]))
        t = np.array([float(r[k]) for k in ("tx", "ty", "tz")])
        key = combination_key(viewpoint_cell(R, t), r["illumination"], r["background"], r["occluder_config"])
        assert key == r["combination_key"] == splits["keys"][r["sample_id"]]
        assert split_of_key.setdefault(key, r["split"]) == r["split"]
        assert int(r["sample_id"]) in splits["splits"][r["split"]]


def test_stats_prints_every_group_and_counts_sum_to_split_size(small_dataset: Path, tmp_path: Path):
    out = {k: str(tmp_path / v) for k, v in (("json", "s.json"), ("csv", "s.csv"), ("plots", "plots"))}
    args = ["stats", str(small_dataset), "--json", out["json"], "--csv", out["csv"], "--plots", out["plots"]]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    for groups in FACTOR_GROUPS.values():
        for g in groups:
            assert f" {g} " in result.output or f"  {g}" in result.output
    stats = json.loads((tmp_path / "s.json").read_text())
    for split, st in stats["splits"].items():
        for factor, groups in FACTOR_GROUPS.items():
            assert set(groups) <= set(st["factors"][factor])
            assert sum(st["factors"][factor].values()) == st["n"], (split, factor)
    assert (tmp_path / "s.csv").read_text().startswith("split,factor,group,count")
    assert len(list((tmp_path / "plots").glob("coverage_*.png"))) == len(stats["splits"])


def test_occlusion_groups_follow_the_paper_thresholds(small_dataset: Path):
    for r in read_metadata(small_dataset):
        r_occ = float(r["r_occ"])
        expected = (
            "none" if r_occ == 0 else "slight" if r_occ <= 0.2 else "moderate" if r_occ <= 0.4 else "heavy"
        )
        assert r["occlusion"] == expected


def test_sample_groups_are_fixed_by_seed(small_dataset: Path, tmp_path: Path):
    args = ["stats", str(small_dataset), "--split", "train", "--sample-groups", "3", "--seed", "7"]
    a = CliRunner().invoke(main, [*args, "--groups-out", str(tmp_path / "a.json")])
    b = CliRunner().invoke(main, [*args, "--groups-out", str(tmp_path / "b.json")])
    assert a.exit_code == 0 and b.exit_code == 0
    ga, gb = (json.loads((tmp_path / n).read_text()) for n in ("a.json", "b.json"))
    assert ga == gb
    train_ids = set(read_json(small_dataset / "splits.json")["splits"]["train"])
    for groups in ga["groups"].values():
        for ids in groups.values():
            assert len(ids) <= 3 and len(set(ids)) == len(ids) and set(ids) <= train_ids


@pytest.mark.parametrize(
    "args, message",
    [
        (["stats", "{tmp}"], "not a dataset folder"),
        (["stats", "{ds}", "--split", "dev"], "unknown split 'dev'"),
    ],
)
def test_stats_errors(small_dataset: Path, tmp_path: Path, args, message):
    args = [a.format(tmp=tmp_path, ds=small_dataset) for a in args]
    result = CliRunner().invoke(main, args)
    assert result.exit_code != 0 and message in result.output
