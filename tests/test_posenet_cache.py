"""The packed training cache and the batch augmentation (data.loader 'cache') against the per-sample path,
on a real rendered dataset and OpenCV itself."""

from __future__ import annotations

import dataclasses
import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
from click.testing import CliRunner
from posenet_helpers import posenet_dataset
from scipy.stats import ks_2samp

from posenet.cli import main
from posenet.config import load_config
from posenet.data import augment, batch_augment, open_split
from posenet.data.cache import CacheDataset, collate, noise_draws, open_cache, resize_indices, warp_indices
from posenet.data.crop import Roi, crop
from posenet.errors import PosenetError

# OpenCV's bilinear warp and resize weigh the same (replicated) source pixels in fixed point (warpAffine:
# 15-bit products of the 1/32 px weights; resize: 11-bit weights, 22-bit products) and round half up,
# against float32 here with round half to even: the weights differ by < 2^-10 of a level at most, so the
# rounded levels differ by at most one, 1/255 in [0, 1]
LEVEL = 1 / 255
FLOAT32 = 1e-5  # float32 rounding of a few operations on values in [0, 1] (eps 1.2e-7, with room)


@pytest.fixture(scope="module")
def dataset_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A writable copy of the shared rendering: the cache is written beside the data."""
    out = tmp_path_factory.mktemp("cache") / "ds"
    shutil.copytree(posenet_dataset(tmp_path_factory), out)
    return out


def batched(*arrays: np.ndarray) -> list[torch.Tensor]:
    """Each array as a batch of one tensor (weights float32, as the cache's items carry them)."""
    return [
        torch.from_numpy(a)[None].float() if a.dtype.kind == "f" else torch.from_numpy(a)[None]
        for a in arrays
    ]


def test_index_replication_matches_opencv_warp_and_resize() -> None:
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, size=(240, 320, 3), dtype=np.uint8)  # noise: every rounding shows
    src = torch.from_numpy(img).permute(2, 0, 1)[None]
    res = 64
    for _ in range(200):
        roi = Roi(rng.uniform((-20, -20), (340, 260)), float(rng.uniform(40, 300)), np.ones(2))
        rows, _, cols, _ = warp_indices(roi, res, (320, 240), nearest=True)
        ours = batch_augment.gather2d(src, *batched(rows[:, 0], cols[:, 0]))[0].permute(1, 2, 0).numpy()
        assert np.array_equal(ours, crop(img, roi, res, nearest=True))
        ours = batch_augment.bilinear(src, *batched(*warp_indices(roi, res, (320, 240), nearest=False)))
        ref = crop(img, roi, res, nearest=False).astype(np.float32)
        assert np.abs(ours[0].permute(1, 2, 0).numpy() - ref).max() <= 1.0
    for _ in range(100):
        side, flip = int(rng.integers(20, 240)), bool(rng.random() < 0.5)
        y, x = int(rng.integers(0, 240 - side + 1)), int(rng.integers(0, 320 - side + 1))
        win = img[y : y + side, x : x + side]
        win = np.ascontiguousarray(win[:, ::-1] if flip else win)
        ref = cv2.resize(win, (res, res), interpolation=cv2.INTER_LINEAR).astype(np.float32)
        indices = (*resize_indices(side, res, y, False), *resize_indices(side, res, x, flip))
        ours = batch_augment.bilinear(src, *batched(*indices))
        assert np.abs(ours[0].permute(1, 2, 0).numpy() - ref).max() <= 1.0


def test_cache_path_gives_the_per_sample_path_items_on_the_same_keys(dataset_dir: Path) -> None:
    cfg = load_config("paper")
    data = dataclasses.replace(cfg.data, bg_pool_size=8)
    ds = open_split(dataset_dir, "train", data, cfg.model_config(), train=True, seed=3)
    folder, _ = open_cache(dataset_dir, ds.instances, data)
    cached = CacheDataset(ds, folder)
    keys = [(e, i) for e in range(4) for i in range(len(ds))]
    raw = collate([cached[k] for k in keys])
    extent = torch.from_numpy(np.asarray(ds.obj.extent, np.float64))
    centres = torch.from_numpy(np.asarray(ds.obj.fps_points, np.float64))
    out = batch_augment.augment_batch(raw, cached.pool_tensor(), extent, centres)
    ref = {k: torch.stack([ds[key][k] for key in keys]) for k in out}
    kinds = raw["bg_kind"]
    assert set(kinds.tolist()) == {0, 1, 2}, "keys must cover no replacement, noise and a pool view"
    # the same draws: the same crop, pose geometry and nearest-neighbour targets, exactly
    for k in out:
        if k != "roi_img":
            assert torch.equal(out[k], ref[k].to(out[k].dtype)), k
    # the image: each pixel's level differs by at most LEVEL before the colour jitter; the jitter
    # ((x - mean) c + mean) b moves a difference d of pixel and mean to b (c d + |1 - c| d), clipping
    # shrinks it. Noise backgrounds draw their grain on the device, and with it their later draws differ
    # (the next test compares their distribution)
    c, b = raw["contrast"].float(), raw["brightness"].float()
    bound = torch.where(raw["color"], b * (c + (1 - c).abs()), 1.0) * LEVEL + FLOAT32
    diff = (out["roi_img"] - ref["roi_img"]).abs().flatten(1).max(1).values
    same = kinds != 1
    assert bool((diff[same] <= bound[same]).all()), (diff[same] - bound[same]).max()


def test_noise_backgrounds_have_the_per_sample_distribution() -> None:
    """Two-sample Kolmogorov-Smirnov tests on 400 backgrounds each at alpha 0.001 (critical D 0.138):
    the mean level (set by the shared coarse draws) and the grain's size (the mean absolute difference
    of horizontal neighbours, set by sigma, drawn apart). A grain 1.5x or 2x too large moves the second
    to D 0.24 or 0.41 (measured once, to show the test can fail)."""
    res, n = 64, 400
    cpu = np.stack([augment.noise_background(res, np.random.default_rng([9, i])) for i in range(n)])
    draws = collate([noise_draws(np.random.default_rng([9, i]), res) for i in range(n)])
    dev = (
        batch_augment.noise_backgrounds(
            draws["cells"], draws["coarse"], draws["sigma"], draws["stars"], draws["star_values"], res
        )
        .permute(0, 2, 3, 1)
        .numpy()
    )
    for stat in (lambda x: x.mean((1, 2, 3)), lambda x: np.abs(np.diff(x, axis=2)).mean((1, 2, 3))):
        assert ks_2samp(stat(cpu), stat(dev), method="asymp").pvalue > 0.001  # the D bound above


def test_cache_is_reused_and_rebuilt_when_the_data_or_the_crop_change(dataset_dir: Path) -> None:
    cfg = load_config("paper")
    ds = open_split(dataset_dir, "train", cfg.data, cfg.model_config(), train=True)
    first, _ = open_cache(dataset_dir, ds.instances, cfg.data)
    again, built = open_cache(dataset_dir, ds.instances, cfg.data)
    assert again == first and not built
    wider, built = open_cache(dataset_dir, ds.instances, dataclasses.replace(cfg.data, dzi_scale=0.4))
    assert wider != first and built
    rgb = ds.instances[0].rgb
    os.utime(rgb, ns=(rgb.stat().st_atime_ns, rgb.stat().st_mtime_ns + 1))
    touched, built = open_cache(dataset_dir, ds.instances, cfg.data)
    assert touched != first and built


def test_cache_loader_is_refused_with_the_augmentations_it_does_not_apply(tmp_path: Path) -> None:
    path = tmp_path / "c.yaml"
    for data in ("{loader: cache, augment: spnv2}", "{loader: cache, truncate_fg: true}", "{loader: disk}"):
        path.write_text(f"preset: smoke\ndata: {data}\n")
        with pytest.raises(PosenetError, match="data.loader"):
            load_config(str(path))


def test_posenet_train_runs_on_the_cache_path_and_says_so(dataset_dir: Path, tmp_path: Path) -> None:
    config = tmp_path / "tiny.yaml"
    config.write_text(
        "preset: smoke\nmodel: {input_res: 64, output_res: 16, head_channels: 32, pnp_channels: 32, "
        "fc_dims: [64, 32]}\ndata: {workers: 1, loader: cache}\n"
        "optim: {batch_size: 4, epochs: 1, threads: 1}\n"  # a core left for the loader process
    )
    res = CliRunner().invoke(main, ["train", "--data", str(dataset_dir), "--out", str(tmp_path / "run"),
                                    "--config", str(config), "--max-steps", "2"])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "1 loader processes (cache path)" in res.output
    assert (tmp_path / "run" / "last.pt").is_file()
