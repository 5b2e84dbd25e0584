"""`data.loader: auto` and `optim.compile: auto`: the packed cache and the compiled step on CUDA, where
they were built for, the per-sample loader and the eager step elsewhere; an explicit value as set. The
decision is a function of the device and the process count, checked here for CUDA without a GPU (a
torch.device names CUDA without touching it), and a CPU run's start-up line says which it took."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from click.testing import CliRunner
from posenet_helpers import TINY_POSE

from posenet.cli import main
from posenet.config import load_config
from posenet.errors import PosenetError
from posenet.training.fast_path import resolve_fast_paths

CUDA, CPU = torch.device("cuda", 0), torch.device("cpu")


def auto_config(tmp_path: Path, extra: str = "") -> Path:
    path = tmp_path / "auto.yaml"
    path.write_text(f"preset: smoke\ndata: {{loader: auto{extra}}}\noptim: {{compile: auto}}\n")
    return path


@pytest.mark.parametrize(
    ("device", "world", "extra", "loader", "compiled"),
    [
        (CUDA, 1, "", "cache", True),
        (CUDA, 2, "", "cache", False),  # the compiled step is not built for DDP
        (CUDA, 1, ", augment: spnv2", "samples", True),  # the cache applies the paper's augmentations only
        (CPU, 1, "", "samples", False),
    ],
)
def test_auto_is_decided_by_the_device(tmp_path, device, world, extra, loader, compiled) -> None:
    cfg = load_config(str(auto_config(tmp_path, extra)))
    resolved, line = resolve_fast_paths(cfg, device, world)
    assert (resolved.data.loader, resolved.optim.compile) == (loader, compiled)
    assert f"data.loader {loader} (auto: " in line and f"step {'compiled' if compiled else 'eager'}" in line
    explicit = load_config("smoke")
    kept, line = resolve_fast_paths(explicit, CUDA, 1)
    assert (kept.data.loader, kept.optim.compile) == ("samples", False) and line.count("as set") == 2


def test_a_bad_switch_is_one_line(tmp_path) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text("preset: smoke\noptim: {compile: sometimes}\n")
    with pytest.raises(PosenetError, match="optim.compile"):
        load_config(str(path))


def test_a_cpu_run_says_it_took_the_per_sample_loader_and_the_eager_step(dataset_dir, tmp_path) -> None:
    config = tmp_path / "tiny_auto.yaml"
    auto = TINY_POSE.replace("data: {workers: 0}", "data: {workers: 0, loader: auto}")
    config.write_text(
        auto.replace("optim: {batch_size: 4, epochs: 1}", "optim: {batch_size: 4, epochs: 1, compile: auto}")
    )
    res = CliRunner().invoke(main, ["train", "--data", str(dataset_dir), "--out", str(tmp_path / "run"),
                                    "--config", str(config), "--max-steps", "1"])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert (
        "paths: data.loader samples (auto: not on CUDA), step eager (optim.compile auto: not on CUDA)"
        in res.output
    )
