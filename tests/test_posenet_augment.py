"""The field's augmentations as options: SPNv2's albumentations chain, GDR-Net's chain and its foreground
truncation, on the real rendered dataset."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import albumentations as A
import numpy as np
import pytest
import torch

from posenet.config import config_from_dict, smoke_config
from posenet.data import open_split
from posenet.data.augment import apply_cut, draw_cut
from posenet.data.photometric import composed, photometric, spnv2_chain
from posenet.errors import PosenetError
from posenet.models import ModelConfig
from scgen.io import usable_cores

MODEL = ModelConfig.create("gdrnet", "smoke")
TARGETS = ("roi_xyz", "roi_mask_visib", "roi_mask_full", "roi_region", "site")


def items(root: Path, **data: object) -> list[dict[str, torch.Tensor]]:
    cfg = dataclasses.replace(smoke_config().data, **data)
    ds = open_split(root, "train", cfg, MODEL, train=True, seed=3)
    return [ds[(1, i)] for i in range(8)]


@pytest.mark.parametrize("name", ["spnv2", "gdrnet-occlusion"])
def test_photometric_chains_change_the_image_only_and_repeat_per_sample(dataset_dir: Path, name: str) -> None:
    plain, chained, again = (items(dataset_dir, augment=a) for a in ("paper", name, name))
    changed = 0
    for p, c, a in zip(plain, chained, again, strict=True):
        for key in TARGETS:
            assert torch.equal(p[key], c[key]), key  # the crop and its targets are drawn before the colours
        assert torch.equal(c["roi_img"], a["roi_img"])  # a function of (seed, epoch, index)
        assert float(c["roi_img"].min()) >= 0.0 and float(c["roi_img"].max()) <= 1.0
        changed += not torch.equal(p["roi_img"], c["roi_img"])
    assert changed >= 6


def test_spnv2_dropout_and_sun_flare_fall_inside_the_target_box() -> None:
    """SPNv2's coarse dropout and sun flare act inside the target box of the crop."""
    res, box = 128, (0.25, 0.375, 0.625, 0.75)
    x0, y0, x1, y1 = (round(v * res) for v in box)
    grey = np.full((res, res, 3), 90, np.uint8)
    dropout, flare = spnv2_chain(box, res)[1:3]
    drop_chain, flare_chain = composed([dropout]), A.Compose([flare], save_applied_params=True)
    holes_seen, suns_seen = 0, 0
    for seed in range(12):  # each applies with p 0.5
        for transform in (dropout, flare):  # after composing: a Compose draws fresh seeds for its transforms
            transform.set_random_seed(seed)
        holes = drop_chain(image=grey, bboxes=[box], labels=["target"])["image"]
        rows, cols = np.nonzero((holes != grey).any(-1))
        if len(rows):
            holes_seen += 1
            assert rows.min() >= y0 - 1 and rows.max() <= y1 and cols.min() >= x0 - 1 and cols.max() <= x1
        applied = flare_chain(image=grey)["applied_transforms"]
        if applied:
            suns_seen += 1
            u, v = applied[0][1]["flare_center"]  # the sun's position
            assert x0 <= u <= x1 and y0 <= v <= y1
    assert holes_seen >= 3 and suns_seen >= 3


def test_truncation_cuts_the_visible_target_and_every_target_follows(dataset_dir: Path) -> None:
    plain = items(dataset_dir, bg_prob=1.0, color_prob=0.0)
    cut = items(dataset_dir, bg_prob=1.0, color_prob=0.0, truncate_fg=True)
    smaller = 0
    for p, c in zip(plain, cut, strict=True):
        v_p, v_c = p["roi_mask_visib"], c["roi_mask_visib"]
        assert bool((v_c <= v_p).all()) and torch.equal(p["roi_mask_full"], c["roi_mask_full"])
        assert bool((c["roi_xyz"] * (1 - v_c) == 0).all()) and bool(
            ((c["roi_region"] > 0) == (v_c[0] > 0)).all()
        )
        smaller += int(v_c.sum() < v_p.sum())
    assert smaller >= 4  # 0.8 of the replacements cut


def test_a_cut_is_one_straight_line_at_every_resolution() -> None:
    mask = np.zeros((64, 64), np.uint8)
    mask[16:48, 8:40] = 1
    cuts = [draw_cut(mask, np.random.default_rng(s)) for s in range(40)]
    assert sum(c is None for c in cuts) in range(3, 15)  # 0.2 of the draws
    for c in filter(None, cuts):
        fine, coarse = apply_cut(mask, c), apply_cut(mask[::4, ::4], c)
        assert 0 < fine.sum() < mask.sum()  # the line lies between the box edge and its centre
        assert np.array_equal(coarse, fine[::4, ::4]) or abs(int(coarse.sum()) * 16 - int(fine.sum())) <= 64


def test_unknown_augment_is_refused() -> None:
    with pytest.raises(PosenetError, match="data.augment"):
        config_from_dict({"preset": "smoke", "data": {"augment": "imgaug"}})
    assert photometric(
        "spnv2", np.zeros((8, 8, 3), np.float32), (2.0, 2.0, 2.0, 2.0), np.random.default_rng(0)
    ).shape == (8, 8, 3)


FORK_AFTER_POOL = """
import sys
from pathlib import Path
import cv2
import numpy as np
from posenet.config import config_from_dict
from posenet.training.train import train
cv2.GaussianBlur(np.zeros((64, 64, 3), np.uint8), (0, 0), 1.0)  # OpenCV's thread pool, used in this process
cfg = config_from_dict({"preset": "smoke", "data": {"workers": 1},
                        "model": {"input_res": 64, "output_res": 16, "head_channels": 32, "pnp_channels": 32,
                                  "fc_dims": [64, 32]},
                        "optim": {"batch_size": 4, "epochs": 1, "threads": 1}})  # a core left for the loader
train(Path(sys.argv[1]), Path(sys.argv[2]), cfg, max_steps=1)
"""


@pytest.mark.skipif(usable_cores() < 2, reason="one core: none left for a loader")
def test_opencv_used_in_the_training_process_does_not_hang_its_loader_processes(
    dataset_dir: Path, tmp_path: Path
) -> None:
    """OpenCV's thread pool does not survive a fork: once the training process has used it (a blur here;
    in a pytest session, the tests that ran before), a forked loader process hung for ever in worker_init's
    cv2.setNumThreads, until posenet.training.train.before_loader_fork."""
    cmd = [sys.executable, "-c", FORK_AFTER_POOL, str(dataset_dir), str(tmp_path / "run")]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "1 loader processes (samples path)" in proc.stdout + proc.stderr  # one was forked
    assert (tmp_path / "run" / "last.pt").is_file()
