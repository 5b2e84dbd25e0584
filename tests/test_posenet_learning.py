"""Learning test: the CPU preset as a user gets it (the paper's augmentations and losses) learns geometry
and pose, not just masks, through the real pipeline (files -> crops and targets -> losses -> Ranger ->
checkpoint -> decode -> errors).

The failure it guards against: a network that learns the mask (brightness gives it) while xyz sits at the
best constant prediction and the rotation error stays at a random rotation's ~126 deg. Three minutes of
2 CPU cores cannot teach a network to generalise to held-out scenes, so this test measures on the
training images; the held-out figures come from `benchmarks/posenet_learning.py` (README).
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from posenet_helpers import posenet_dataset

from posenet.config import config_from_dict, load_config
from posenet.data import open_split
from posenet.evaluate import evaluate, load_model
from posenet.train import steps_per_epoch, train

STEPS = 1200  # at the preset's batch of 8 (about 3 minutes on 2 idle cores)
# Measured from the ImageNet Lite0 on 2 threads, a 1200-step schedule: ratio 0.56 and median 52.5 deg at
# step 600, 0.42 and 8.8 deg at 900, 0.32 and 3.7 deg at 1200. A 600-step schedule was too close to where
# pose emerges: 0.69 and 109 deg on 2 threads, 0.53 and 39 deg on one. The failure this guards against
# gave ~0.97 and ~126 deg (a random rotation).
MAX_XYZ_RATIO = 0.7
MAX_MEDIAN_RE_DEG = 45.0


@pytest.fixture(scope="module")
def dataset_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return posenet_dataset(tmp_path_factory)


def xyz_errors(ckpt: Path, data: Path) -> tuple[float, float]:
    """(network, best constant) mean L1 of normalised xyz over the visible pixels of the training crops.

    The crops are the evaluation crops (no jitter, no augmentation); the best constant is the per-axis
    median of every visible target, the minimum of an L1 loss that ignores the image.
    """
    model, state = load_model(ckpt, torch.device("cpu"))
    trained = config_from_dict(state["config"]).data
    plain = dataclasses.replace(trained, dzi_prob=0.0, color_prob=0.0, bg_prob=0.0)
    dataset = open_split(data, "train", plain, model.config, train=True)
    predicted, target = [], []
    with torch.inference_mode():
        for i in range(len(dataset)):
            item = dataset[i]
            visible = item["roi_mask_visib"][0] > 0
            out = model(item["roi_img"][None], item["roi_coord2d"][None])
            predicted.append(out["xyz"][0][:, visible].T.numpy())
            target.append(item["roi_xyz"][:, visible].T.numpy())
    pred, gt = np.concatenate(predicted), np.concatenate(target)
    constant = np.abs(gt - np.median(gt, axis=0)).sum(1).mean()
    return float(np.abs(pred - gt).sum(1).mean()), float(constant)


def test_the_cpu_preset_learns_geometry_and_pose_not_just_masks(dataset_dir: Path, tmp_path: Path) -> None:
    cfg = load_config("smoke")
    instances = open_split(dataset_dir, "train", cfg.data, cfg.model_config(), train=True).instances
    cfg.optim.epochs = STEPS // steps_per_epoch(len(instances), cfg.optim)
    cfg.optim.ckpt_every = cfg.optim.epochs  # one checkpoint, not one per 2-step epoch: learning unchanged
    tic = time.perf_counter()
    ckpt = train(dataset_dir, tmp_path / "run", cfg)
    trained_s = time.perf_counter() - tic
    network, constant = xyz_errors(ckpt, dataset_dir)
    result = evaluate(dataset_dir, ckpt, "train", image_ids={i.im_id for i in instances}, workers=0)
    re = np.array([r["re_deg"] for r in result.records])
    print(
        f"\n{len(instances)} training images, {cfg.optim.epochs} epochs in {trained_s:.0f} s: "
        f"xyz L1 {network:.3f} vs best constant {constant:.3f} (ratio {network / constant:.2f}, "
        f"must be <= {MAX_XYZ_RATIO}); rotation error median {np.median(re):.1f} deg "
        f"(must be <= {MAX_MEDIAN_RE_DEG}; a random rotation: ~126)"
    )
    assert network <= MAX_XYZ_RATIO * constant
    assert np.median(re) <= MAX_MEDIAN_RE_DEG
