"""Learning test: the CPU preset as a user gets it (the paper's augmentations and losses) learns geometry
and pose, not just masks, through the real pipeline (files -> crops and targets -> losses -> Ranger ->
checkpoint -> decode -> errors).

The failure it guards against: a network that learns the mask (brightness gives it) while xyz sits at the
best constant prediction and the rotation error stays at a random rotation's ~126 deg. A few minutes of
2 CPU cores on 16 images fit geometry and pose on those images, so xyz, rotation and translation are
measured on the training images. What generalises in that budget is measured on 32 held-out crops (the
set's 8 val and test images and 24 images of another seed, scenes the training never saw): the visible
mask, against the best mask that ignores the image. Held-out pose comes from the benchmarks
(`benchmarks/figures/posenet_control.py`, `benchmarks/figures/posenet_learning.py`; docs/benchmarks.md).
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from posenet_helpers import posenet_dataset

from posenet.checkpoint import load_model
from posenet.config import config_from_dict, load_config
from posenet.data import open_split
from posenet.evaluation.evaluate import evaluate
from posenet.geometry import roi_translation
from posenet.training.train import steps_per_epoch, train

STEPS = 1200  # at the preset's batch of 8 (~10 minutes of training on an idle core: 585 s on 2026-11-29)
# Measured from the ImageNet Lite0 on 2 threads, a 1200-step schedule: ratio 0.56 and median 52.5 deg at
# step 600, 0.42 and 8.8 deg at 900, 0.32 and 3.7 deg at 1200 (channels-last: 0.33 and 4.3 deg). A
# 600-step schedule was too close to where pose emerges: 0.69 and 109 deg on 2 threads, 0.53 and 39 deg
# on one. An 800-step one (2:56 for the whole test) passes xyz and rotation (0.47, 13.5 deg) and the
# translation (ratio 0.48) but its held-out mask is no better than the constant one (IoU 0.34 vs 0.33).
# The failure this guards against gave ~0.97 and ~126 deg (a random rotation).
MAX_XYZ_RATIO = 0.7
MAX_MEDIAN_RE_DEG = 45.0
# Measured at 1200 steps on 2 idle cores (2026-11-27), the margin to each bound in brackets:
# - training images: xyz ratio 0.34 (2x under 0.7), rotation median 2.9 deg (15x under 45), translation
#   error median 2.8 cm against the constant SITE's 12.7 cm (ratio 0.22, 2.7x under 0.6);
# - held out (32 crops): mask IoU 0.34 against the majority mask's 0.28, a paired gain of 0.060 with a
#   standard error of 0.029 (2 standard errors above 0; one crop moves it by about 0.005). The held-out
#   translation is not learned in this budget: ratio 1.06 on the 32 crops. The 8 held-out images this test
#   had alone gave 0.28 (their box-alone constant errs by 34 cm, the other 24's by 10 cm), which is how a
#   bound of 0.6 on them passed.
# A network that ignores the image gives a mask gain of ~0 and a translation ratio of ~1.
MIN_MASK_IOU_GAIN = 0.0
MAX_TE_RATIO = 0.6
# The training's intra-op threads: one. Every machine has that one core, so the summation order, and with
# it every figure below, is the same on a CI machine of any core count. It also leaves the second core to
# the suite's other pytest-xdist process: alone on 2 idle cores one thread trained in 585 s (user + sys
# 684 s with the 2 loader processes, 2026-11-29) where 2 threads took 572 s (2026-11-27), so the second
# thread bought ~2 % and, beside the other process, made 3 threads on 2 cores (in the suite: 767 s on two
# threads, 750 s on one).
# The verdicts do not rest on one order's rounding. With Ranger's RAdam run through the fused Adam kernel
# (2026-11-29), one thread gave xyz ratio 0.33, translation ratio 0.25, rotation median 2.6 deg, held-out
# mask IoU 0.34 vs 0.28; 2 threads gave 0.33, 0.47, 13.9 deg (the median of 16 images: a few images
# turning decide it), 0.33 vs 0.28; the foreach RAdam that day, 2 threads, 0.32, 0.34, 3.1 deg, 0.33 vs
# 0.28. One thread with the foreach RAdam (2026-11-28): 0.34, 0.23, 3.3 deg, 0.32 vs 0.28. The
# translation bound's margin is the thinnest (1.3x at 0.47 on 2 threads, 2.4x at 0.25 on one).
THREADS = 1


@pytest.fixture(scope="module")
def unseen_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """More held-out scenes: another seed's images, every split of them."""
    return posenet_dataset(tmp_path_factory, seed=1)


def crops(ckpt: Path, data: Path, splits: tuple[str, ...]) -> list[dict[str, torch.Tensor]]:
    """Each training-mode crop of `splits` (every target; no jitter, no augmentation) with the network's
    outputs on it: the targets and crop geometry of the dataset item, plus `xyz_pred` and `xyz_gt` on
    the visible pixels, the visible masks `mask_pred` and `mask_gt`, and the translation `t_pred`."""
    model, state = load_model(ckpt, torch.device("cpu"))
    trained = config_from_dict(state["config"]).data
    plain = dataclasses.replace(trained, dzi_prob=0.0, color_prob=0.0, bg_prob=0.0)
    datasets = [open_split(data, split, plain, model.config, train=True) for split in splits]
    items = [ds[i] for ds in datasets for i in range(len(ds))]
    result = []
    with torch.inference_mode():
        for item in items:
            out = model(item["roi_img"][None], item["roi_coord2d"][None])
            visible = item["roi_mask_visib"][0] > 0
            result.append(
                {
                    **item,
                    "xyz_pred": out["xyz"][0][:, visible].T,
                    "xyz_gt": item["roi_xyz"][:, visible].T,
                    "mask_pred": out["mask"][0, 0] > 0,
                    "mask_gt": visible,
                    "t_pred": roi_translation(out["site"][0], item),
                }
            )
    return result


def xyz_errors(train_crops: list[dict[str, torch.Tensor]]) -> tuple[float, float]:
    """(network, best constant) mean L1 of normalised xyz over the visible pixels of the crops; the best
    constant is the per-axis median of every visible target, the minimum of an L1 loss that ignores the
    image."""
    pred = torch.cat([c["xyz_pred"] for c in train_crops]).numpy()
    gt = torch.cat([c["xyz_gt"] for c in train_crops]).numpy()
    constant = np.abs(gt - np.median(gt, axis=0)).sum(1).mean()
    return float(np.abs(pred - gt).sum(1).mean()), float(constant)


def mask_ious(
    train_crops: list[dict[str, torch.Tensor]], held_out: list[dict[str, torch.Tensor]]
) -> tuple[float, float]:
    """(network, best constant) mean IoU of the visible mask on the held-out crops; the constant is the
    training crops' majority mask (each pixel on where most training targets are), the best mask that
    ignores the image."""
    majority = torch.stack([c["mask_gt"] for c in train_crops]).float().mean(0) > 0.5

    def iou(a: torch.Tensor, b: torch.Tensor) -> float:
        return float((a & b).sum() / (a | b).sum().clamp(min=1))

    network = np.mean([iou(c["mask_pred"], c["mask_gt"]) for c in held_out])
    constant = np.mean([iou(majority, c["mask_gt"]) for c in held_out])
    return float(network), float(constant)


def translation_errors(train_crops: list[dict[str, torch.Tensor]]) -> tuple[float, float]:
    """(network, best constant) median translation error (m) on the training crops; the constant is the
    per-component median SITE (offset from the crop centre, zoom-invariant depth) of the training
    targets, decoded in each crop: the translation that the box alone gives."""
    site = torch.stack([c["site"] for c in train_crops]).median(0).values
    network = [float((c["t_pred"] - c["t"]).norm()) for c in train_crops]
    constant = [float((roi_translation(site, c) - c["t"]).norm()) for c in train_crops]
    return float(np.median(network)), float(np.median(constant))


def test_the_cpu_preset_learns_geometry_and_pose_not_just_masks(
    dataset_dir: Path, unseen_dir: Path, tmp_path: Path
) -> None:
    cfg = load_config("smoke")
    instances = open_split(dataset_dir, "train", cfg.data, cfg.model_config(), train=True).instances
    cfg.optim.epochs = STEPS // steps_per_epoch(len(instances), cfg.optim)
    cfg.optim.threads = THREADS  # not one per core: see THREADS
    cfg.optim.ckpt_every = cfg.optim.epochs  # one checkpoint, not one per 2-step epoch: learning unchanged
    tic = time.perf_counter()
    ckpt = train(dataset_dir, tmp_path / "run", cfg)
    trained_s = time.perf_counter() - tic
    train_crops = crops(ckpt, dataset_dir, ("train",))
    held_out = crops(ckpt, dataset_dir, ("val", "test")) + crops(ckpt, unseen_dir, ("train", "val", "test"))
    xyz, xyz_constant = xyz_errors(train_crops)
    mask, mask_constant = mask_ious(train_crops, held_out)
    te, te_constant = translation_errors(train_crops)
    result = evaluate(dataset_dir, ckpt, "train", image_ids={i.im_id for i in instances}, workers=0)
    re = np.median([r["re_deg"] for r in result.records])
    print(
        f"\n{len(instances)} training images, {cfg.optim.epochs} epochs in {trained_s:.0f} s; "
        f"{len(held_out)} held-out crops. Network vs best constant: "
        f"train xyz L1 {xyz:.3f} vs {xyz_constant:.3f} (ratio {xyz / xyz_constant:.2f}, must be <= "
        f"{MAX_XYZ_RATIO}); held-out mask IoU {mask:.2f} vs {mask_constant:.2f} (must gain > "
        f"{MIN_MASK_IOU_GAIN}); train translation error median {te * 100:.1f} vs "
        f"{te_constant * 100:.1f} cm (ratio {te / te_constant:.2f}, must be <= {MAX_TE_RATIO}); "
        f"train rotation error median {re:.1f} deg (must be <= {MAX_MEDIAN_RE_DEG}; a random rotation: ~126)"
    )
    assert xyz <= MAX_XYZ_RATIO * xyz_constant
    assert mask > mask_constant + MIN_MASK_IOU_GAIN
    assert te <= MAX_TE_RATIO * te_constant
    assert re <= MAX_MEDIAN_RE_DEG
