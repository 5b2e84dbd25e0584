"""Learning test: a reduced-width network overfits a few rendered images through the real pipeline
(files -> crops and targets -> losses -> Ranger -> checkpoint -> decode -> ADD), which only works when
data, targets, losses and pose decoding agree with each other."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest
from posenet_helpers import posenet_dataset

from posenet.config import config_from_dict
from posenet.data import open_split
from posenet.evaluate import evaluate
from posenet.train import train

FIT = {
    "preset": "smoke",
    # 64² input and one hidden FC layer: GDR-Net's tiny init (std 0.001) wakes up in fewer steps
    "model": {"input_res": 64, "output_res": 16, "fc_dims": [128]},
    # no augmentation: training crops are the evaluation crops, so the network can memorise them
    "data": {"workers": 1, "color_prob": 0.0, "bg_prob": 0.0, "dzi_prob": 0.0},
    "optim": {"batch_size": 7, "warmup_iters": 20, "ckpt_every": 10**6},
}
STEPS_PER_EPOCH = 2  # 16 training instances, batches of 7


@pytest.fixture(scope="module")
def dataset_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return posenet_dataset(tmp_path_factory)


@pytest.mark.parametrize(
    ("variant", "steps", "lr"),
    [
        ("gdrnet", 800, 3e-2),
        pytest.param(
            "gap-gdrnet",
            1600,
            1e-2,
            marks=pytest.mark.slow,
        ),
    ],
)
def test_overfits_its_training_images(
    variant: str, steps: int, lr: float, dataset_dir: Path, tmp_path: Path
) -> None:
    optim = {**FIT["optim"], "epochs": steps // STEPS_PER_EPOCH, "lr": lr}
    cfg = config_from_dict({**FIT, "variant": variant, "optim": optim})
    tic = time.perf_counter()
    ckpt = train(dataset_dir, tmp_path / "run", cfg)
    rows = [json.loads(line) for line in (tmp_path / "run" / "train_log.jsonl").read_text().splitlines()]
    trained = open_split(dataset_dir, "train", cfg.data, cfg.model_config(), train=True).instances
    assert len(trained) // cfg.optim.batch_size == STEPS_PER_EPOCH and len(rows) == steps
    result = evaluate(dataset_dir, ckpt, "train", image_ids={i.im_id for i in trained}, workers=0)
    first = sum(r["loss"] for r in rows[:5]) / 5
    last = sum(r["loss"] for r in rows[-5:]) / 5
    s = result.summary
    print(
        f"\n{variant}: {steps} steps in {time.perf_counter() - tic:.0f} s, loss {first:.3f} -> {last:.3f} "
        f"(x{first / last:.1f}), on {s['n']} training images: ADD@0.1d {s['add_0.1d']:.2f}, "
        f"re {s['re_deg']:.2f} deg, te {s['te_m']:.4f} m"
    )
    assert first / last >= 5.0
    assert s["n"] == len(trained) and s["add_0.1d"] >= 0.8
