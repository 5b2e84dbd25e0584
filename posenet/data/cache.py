"""A packed training cache (`data.loader: cache`): every image decoded once, the pixel work on the batch.

`open_cache` builds, once per dataset and crop settings, three memory-mappable numpy files under
DATA/.posenet_cache/train-KEY/: per training instance the uint8 RGB pixels and masks (bit 0 visible,
bit 1 full) of the image region any DZI crop can reach (`reach`), and its xyz map as stored (float32
metres over xyz_box); KEY hashes the instances' files (paths, sizes, mtimes) and the crop settings, so a
changed dataset or crop gets a cache of its own. `CacheDataset` items are then cheap: the per-sample
path's random draws (same generator, same order) turned into source indices and weights that replicate
OpenCV's warpAffine/resize arithmetic (`warp_indices`, `resize_indices`), and the source windows those
indices touch. `BatchLoader` collates them and runs posenet.data.batch_augment on the training device.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import DataLoader

from posenet.config import DataConfig
from posenet.data import batch_augment
from posenet.data.crop import Roi, crop_affine
from posenet.data.dataset import PoseDataset, roi_geometry
from posenet.data.io import read_bgr, read_mask, read_xyz
from posenet.data.layout import Instance
from posenet.data.sampler import EpochSampler
from posenet.geometry import site_encode

CACHE_DIR = ".posenet_cache"
FORMAT = 1  # bump when the files' layout changes
# per instance: pixel offset, region x0, y0, w, h; xyz offset, xyz_box x0, y0, w, h
INDEX_COLUMNS = 10
MARGIN = 2  # pixels past the crop square that bilinear's second neighbour and coordinate rounding reach


def reach(inst: Instance, cfg: DataConfig) -> tuple[int, int, int, int]:
    """The image region (x0, y0, x1, y1, clipped to the image) that every DZI crop of `inst` lies in:
    crop_from_box's largest side, shifted by its largest shift, plus MARGIN."""
    x, y, w, h = inst.bbox_obj
    w, h = max(float(w), 1.0), max(float(h), 1.0)
    jitter = cfg.dzi_prob > 0
    side = min(max(w, h) * cfg.pad_scale * (1 + cfg.dzi_scale * jitter), float(max(inst.image_size)))
    cx, cy = x + (w - 1) / 2, y + (h - 1) / 2
    half_w = side / 2 + cfg.dzi_shift * w * jitter + MARGIN
    half_h = side / 2 + cfg.dzi_shift * h * jitter + MARGIN
    width, height = inst.image_size
    return (
        max(0, math.floor(cx - half_w)),
        max(0, math.floor(cy - half_h)),
        min(width, math.ceil(cx + half_w) + 1),
        min(height, math.ceil(cy + half_h) + 1),
    )


def cache_key(instances: list[Instance], cfg: DataConfig) -> str:
    """What the cache's contents depend on: the files read (path, size, mtime) and the crop settings."""
    files = []
    for inst in instances:
        for p in (inst.rgb, inst.mask, inst.mask_visib, inst.xyz):
            st = p.stat()
            files.append([str(p), st.st_size, st.st_mtime_ns])
        files.append([list(inst.bbox_obj), list(inst.xyz_box), list(inst.image_size)])
    crop = [cfg.pad_scale, cfg.dzi_scale, cfg.dzi_shift, cfg.dzi_prob > 0]
    blob = json.dumps([FORMAT, crop, files]).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def build_cache(folder: Path, instances: list[Instance], cfg: DataConfig) -> None:
    """Decode every instance once into `folder` (index.npy, pixels.npy, xyz.npy); written to a sibling
    and renamed, so a reader never sees half a cache."""
    regions = [reach(i, cfg) for i in instances]
    index = np.zeros((len(instances), INDEX_COLUMNS), np.int64)
    pix_off = xyz_off = 0
    for row, inst, (x0, y0, x1, y1) in zip(index, instances, regions, strict=True):
        xw, xh = inst.xyz_box[2:]
        row[:] = (pix_off, x0, y0, x1 - x0, y1 - y0, xyz_off, *inst.xyz_box[:2], xw, xh)
        pix_off += (x1 - x0) * (y1 - y0) * 4
        xyz_off += xw * xh * 3
    tmp = folder.with_name(f"{folder.name}.partial-{os.getpid()}")
    tmp.mkdir(parents=True, exist_ok=True)
    pixels = np.lib.format.open_memmap(tmp / "pixels.npy", "w+", np.uint8, (pix_off,))
    xyz = np.lib.format.open_memmap(tmp / "xyz.npy", "w+", np.float32, (xyz_off,))
    for row, inst in zip(index, instances, strict=True):
        po, x0, y0, w, h, xo, _, _, xw, xh = (int(v) for v in row)
        rgb = read_bgr(inst.rgb)[y0 : y0 + h, x0 : x0 + w, ::-1]
        masks = read_mask(inst.mask_visib) | (read_mask(inst.mask) << 1)
        rgbm = np.concatenate([rgb, masks[y0 : y0 + h, x0 : x0 + w, None]], axis=2)
        pixels[po : po + w * h * 4] = rgbm.reshape(-1)
        stored = read_xyz(inst.xyz)
        if stored.shape[:2] != (xh, xw):
            raise ValueError(f"xyz map {inst.xyz} is {stored.shape[1]}x{stored.shape[0]}, xyz_box {xw}x{xh}")
        xyz[xo : xo + xw * xh * 3] = stored.reshape(-1)
    pixels.flush()
    xyz.flush()
    del pixels, xyz
    np.save(tmp / "index.npy", index)
    try:
        tmp.rename(folder)
    except OSError:  # another process built it meanwhile: keep theirs
        shutil.rmtree(tmp, ignore_errors=True)


def open_cache(root: Path, instances: list[Instance], cfg: DataConfig) -> tuple[Path, bool]:
    """The cache folder of these training instances under `root`, and whether it was built just now."""
    folder = root / CACHE_DIR / f"train-{cache_key(instances, cfg)}"
    built = not (folder / "index.npy").is_file()
    if built:
        build_cache(folder, instances, cfg)
    return folder, built


# ---- OpenCV's arithmetic, replicated (tests/test_posenet_cache.py checks it against cv2) -------------
AB_BITS, INTER_BITS = 10, 5  # warpAffine's fixed point: 1/1024 px, bilinear weights in 1/32 px
RESIZE_BITS = 11  # resize's INTER_RESIZE_COEF_BITS


def warp_indices(
    roi: Roi, res: int, size: tuple[int, int], nearest: bool, offset: tuple[int, int] = (0, 0)
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Source (rows, wy, cols, wx) of crop.crop(img, roi, res, nearest, offset) for an image of `size`
    (w, h): rows/cols are res x 2 indices (-1 outside the image), wy/wx the second one's weight (nearest:
    both indices equal, weight 0). warpAffine inverts the affine, then computes a column's source as
    round(M0 x 1024) + round(M2 1024) and a row's as round((M4 y + M5) 1024), in 1/1024 px, rounding to
    the nearest pixel (nearest) or to 1/32 px (bilinear)."""
    m = crop_affine(roi, res, offset).reshape(-1)
    d = 1.0 / (m[0] * m[4] - m[1] * m[3])
    a11, a22 = m[4] * d, m[0] * d
    b1, b2 = -a11 * m[2] - (m[1] * -d) * m[5], -(m[3] * -d) * m[2] - a22 * m[5]
    j = np.arange(res)
    shift = AB_BITS if nearest else AB_BITS - INTER_BITS
    delta = 1 << (shift - 1)
    fx = np.rint(a11 * j * (1 << AB_BITS)).astype(np.int64) + int(np.rint(b1 * (1 << AB_BITS))) + delta
    fy = np.rint((a22 * j + b2) * (1 << AB_BITS)).astype(np.int64) + delta
    out = []
    for fixed, n in ((fy, size[1]), (fx, size[0])):
        fixed = fixed >> shift
        first = fixed if nearest else fixed >> INTER_BITS
        weight = np.zeros(res) if nearest else (fixed & ((1 << INTER_BITS) - 1)) / (1 << INTER_BITS)
        pair = np.stack([first, first + (0 if nearest else 1)], axis=1)
        out += [np.where((pair >= 0) & (pair < n), pair, -1), weight]
    return out[0], out[1], out[2], out[3]


def resize_indices(side: int, res: int, start: int, flip: bool) -> tuple[np.ndarray, np.ndarray]:
    """Source (indices res x 2, second weight) of cv2.resize(INTER_LINEAR) from `side` to `res` pixels of
    a window starting at `start` (flipped: read right to left): OpenCV's float32 source coordinate,
    clamped at the edges, and its weight in RESIZE_BITS fixed point."""
    f = ((np.arange(res) + 0.5) * (side / res) - 0.5).astype(np.float32)
    first = np.floor(f).astype(np.int64)
    w = (f - first).astype(np.float32)
    w, first = np.where(first < 0, 0, w), np.maximum(first, 0)
    w, first = np.where(first >= side - 1, 0, w), np.minimum(first, side - 1)
    pair = np.stack([first, np.minimum(first + 1, side - 1)], axis=1)
    w = np.rint(w * (1 << RESIZE_BITS)) / (1 << RESIZE_BITS)
    return start + (side - 1 - pair if flip else pair), w


def noise_draws(rng: np.random.Generator, res: int) -> dict[str, torch.Tensor]:
    """augment.noise_background's draws, in its order, but the grain's (batch_augment draws it), for
    batch_augment.noise_backgrounds; the stars padded to res // 4 + 1 with -1."""
    stars_max = res // 4 + 1
    cells = int(rng.integers(2, 17))
    coarse = torch.zeros(3, batch_augment.MAX_CELLS, batch_augment.MAX_CELLS)
    grid = rng.uniform(0.0, rng.uniform(0.1, 1.0), size=(cells, cells, 3)).astype(np.float32)
    coarse[:, :cells, :cells] = torch.from_numpy(grid.transpose(2, 0, 1))
    sigma = float(np.float32(rng.uniform(0.0, 0.05)))
    xy = rng.integers(0, res, size=(int(rng.integers(0, stars_max)), 2))
    values = rng.uniform(0.5, 1.0, size=len(xy))
    stars = torch.full((stars_max, 2), -1, dtype=torch.int64)
    stars[: len(xy)] = torch.from_numpy(xy)
    star_values = torch.zeros(stars_max)
    star_values[: len(xy)] = torch.from_numpy(values).float()
    return {"bg_kind": torch.tensor(1), "cells": torch.tensor(cells), "coarse": coarse,
            "sigma": torch.tensor(sigma), "stars": stars, "star_values": star_values}  # fmt: skip


# ---- the dataset and its loader -----------------------------------------------------------------------
class CacheDataset(PoseDataset):
    """PoseDataset's training items from the cache at `folder`, their pixel work left to the batch
    (batch_augment.augment_batch): each item holds its draws, source indices and source windows."""

    def __init__(self, base: PoseDataset, folder: Path) -> None:
        super().__init__(
            base.instances, base.obj, base.cfg, base.input_res, base.output_res, True, None, base.seed
        )
        self.folder = folder
        self.index = np.load(folder / "index.npy")
        self._pixels: np.ndarray | None = None  # memory maps, opened in each loader process
        self._xyz: np.ndarray | None = None
        self.pool = self.bg_pool_instances()

    def _maps(self) -> tuple[np.ndarray, np.ndarray]:
        if self._pixels is None or self._xyz is None:
            self._pixels = np.load(self.folder / "pixels.npy", mmap_mode="r")
            self._xyz = np.load(self.folder / "xyz.npy", mmap_mode="r")
        return self._pixels, self._xyz

    def pool_tensor(self) -> torch.Tensor:
        """The background pool (the per-sample path's target-free images), P x 3 x H x W uint8 RGB,
        zero-padded to the largest; at least one (blank) image so that indexing stays valid."""
        images = [self._target_free(i) for i in self.pool] or [np.zeros((1, 1, 3), np.uint8)]
        h, w = max(i.shape[0] for i in images), max(i.shape[1] for i in images)
        out = torch.zeros(len(images), 3, h, w, dtype=torch.uint8)
        for k, img in enumerate(images):
            out[k, :, : img.shape[0], : img.shape[1]] = torch.from_numpy(img.transpose(2, 0, 1))
        return out

    def __getitem__(self, index: int | tuple[int, int]) -> dict[str, torch.Tensor]:
        epoch, idx = index if isinstance(index, tuple) else (0, index)
        inst = self.instances[idx]
        rng = np.random.default_rng([self.seed, epoch, idx])
        roi = self._roi(inst, rng)  # PoseDataset's draws, in its order
        R, r = self.input_res, self.output_res
        item: dict[str, torch.Tensor] = {
            **roi_geometry(roi, inst.K, inst.image_size, r),
            "R": torch.from_numpy(inst.R).float(),
            "t": torch.from_numpy(inst.t).float(),
            "key": torch.tensor(inst.key),
        }
        item["site"] = site_encode(
            item["t"], item["K"], item["crop_center"], item["box_wh"], item["resize_ratio"]
        )
        item |= self._draws(rng)
        po, x0, y0, w, h, xo, _, _, xw, xh = (int(v) for v in self.index[idx])
        img_rows, img_wy, img_cols, img_wx = warp_indices(roi, R, inst.image_size, nearest=False)
        keep_rows, _, keep_cols, _ = warp_indices(roi, R, inst.image_size, nearest=True)
        mask_rows, _, mask_cols, _ = warp_indices(roi, r, inst.image_size, nearest=True)
        xyz_rows, _, xyz_cols, _ = warp_indices(roi, r, (xw, xh), nearest=True, offset=inst.xyz_box[:2])
        pixels, xyz = self._maps()
        region = pixels[po : po + w * h * 4].reshape(h, w, 4)
        rows = [img_rows, keep_rows[:, 0], mask_rows[:, 0]]
        cols = [img_cols, keep_cols[:, 0], mask_cols[:, 0]]
        window, (wy0, wx0) = _window(region, rows, cols, (y0, x0))
        xyz_window, (zy0, zx0) = _window(xyz[xo : xo + xw * xh * 3].reshape(xh, xw, 3), [xyz_rows[:, 0]],
                                         [xyz_cols[:, 0]], (0, 0))  # fmt: skip
        item |= {
            "window": torch.from_numpy(np.ascontiguousarray(window.transpose(2, 0, 1))),
            "xyz": torch.from_numpy(np.ascontiguousarray(xyz_window.transpose(2, 0, 1))),
            "img_rows": _shifted(img_rows, wy0), "img_cols": _shifted(img_cols, wx0),
            "img_wy": torch.from_numpy(img_wy).float(), "img_wx": torch.from_numpy(img_wx).float(),
            "keep_rows": _shifted(keep_rows[:, 0], wy0), "keep_cols": _shifted(keep_cols[:, 0], wx0),
            "mask_rows": _shifted(mask_rows[:, 0], wy0), "mask_cols": _shifted(mask_cols[:, 0], wx0),
            "xyz_rows": _shifted(xyz_rows[:, 0], zy0), "xyz_cols": _shifted(xyz_cols[:, 0], zx0),
        }  # fmt: skip
        return item

    def _draws(self, rng: np.random.Generator) -> dict[str, torch.Tensor]:
        """PoseDataset._roi_image's background and colour draws, in its order, as tensors (noise: all
        but the fine grain's, see batch_augment); unused fields are zeros of fixed shape."""
        cfg, R = self.cfg, self.input_res
        stars_max = R // 4 + 1
        cells = batch_augment.MAX_CELLS
        out = {
            "bg_kind": torch.tensor(0), "pool_index": torch.tensor(0),
            "cells": torch.tensor(2), "coarse": torch.zeros(3, cells, cells),
            "sigma": torch.tensor(0.0), "stars": torch.full((stars_max, 2), -1, dtype=torch.int64),
            "star_values": torch.zeros(stars_max),
            "bg_rows": torch.zeros(R, 2, dtype=torch.int64), "bg_wy": torch.zeros(R),
            "bg_cols": torch.zeros(R, 2, dtype=torch.int64), "bg_wx": torch.zeros(R),
        }  # fmt: skip
        if rng.random() < cfg.bg_prob:
            if rng.random() >= cfg.bg_from_dataset or cfg.bg_pool_size == 0:
                out |= noise_draws(rng, R)
            else:
                out |= self._view_draws(rng)
        color = bool(rng.random() < cfg.color_prob)
        c, b = (rng.uniform(*cfg.contrast), rng.uniform(*cfg.brightness)) if color else (1.0, 1.0)
        return out | {
            "color": torch.tensor(color),
            "contrast": torch.tensor(c),
            "brightness": torch.tensor(b),
        }

    def _view_draws(self, rng: np.random.Generator) -> dict[str, torch.Tensor]:
        """PoseDataset._background's pool pick and augment.random_view's window and flip draws."""
        k = int(rng.integers(len(self.pool)))
        w, h = self.pool[k].image_size
        side = int(rng.integers(min(h, w) // 3, min(h, w) + 1))
        y, x = int(rng.integers(0, h - side + 1)), int(rng.integers(0, w - side + 1))
        flip = bool(rng.random() < 0.5)
        rows, wy = resize_indices(side, self.input_res, y, False)
        cols, wx = resize_indices(side, self.input_res, x, flip)
        return {"bg_kind": torch.tensor(2), "pool_index": torch.tensor(k),
                "bg_rows": torch.from_numpy(rows), "bg_wy": torch.from_numpy(wy).float(),
                "bg_cols": torch.from_numpy(cols), "bg_wx": torch.from_numpy(wx).float()}  # fmt: skip


def _window(
    src: np.ndarray, rows: list[np.ndarray], cols: list[np.ndarray], origin: tuple[int, int]
) -> tuple[np.ndarray, tuple[int, int]]:
    """The part of `src` (a region of the image starting at `origin` = (y, x)) that the image indices
    `rows`/`cols` touch, and that part's origin in image pixels."""
    out, start = [], []
    for idx, o, n in ((rows, origin[0], src.shape[0]), (cols, origin[1], src.shape[1])):
        valid = np.concatenate([i[i >= 0].reshape(-1) for i in idx])
        # nothing touched: one pixel, never read, keeps the window's shape valid
        lo, hi = (int(valid.min()), int(valid.max()) + 1) if len(valid) else (o, o + 1)
        if lo < o or hi > o + n:
            raise ValueError(f"crop reaches pixels {lo}..{hi} outside the cached region {o}..{o + n}")
        out.append(slice(lo - o, hi - o))
        start.append(lo)
    return src[out[0], out[1]], (start[0], start[1])


def _shifted(idx: np.ndarray, origin: int) -> torch.Tensor:
    """Image indices made window indices (-1 stays -1)."""
    return torch.from_numpy(np.where(idx >= 0, idx - origin, -1))


def collate(items: list[dict[str, torch.Tensor]]) -> dict[str, torch.Tensor]:
    """Stack the items; the windows zero-padded to the batch's largest (the padding is never indexed)."""
    out = {}
    for k in items[0]:
        if k in ("window", "xyz"):
            h, w = max(i[k].shape[1] for i in items), max(i[k].shape[2] for i in items)
            stacked = items[0][k].new_zeros(len(items), items[0][k].shape[0], h, w)
            for b, i in enumerate(items):
                stacked[b, :, : i[k].shape[1], : i[k].shape[2]] = i[k]
            out[k] = stacked
        else:
            out[k] = torch.stack([i[k] for i in items])
    return out


class BatchLoader:
    """The cache path's loader: `loader`'s collated raw batches, moved to `device` and made training
    batches there (batch_augment.augment_batch)."""

    def __init__(self, loader: DataLoader, dataset: CacheDataset, device: torch.device) -> None:
        self.loader, self.device = loader, device
        self.pool = dataset.pool_tensor().to(device)
        self.extent = torch.from_numpy(np.asarray(dataset.obj.extent, np.float64)).to(device)
        self.centres = torch.from_numpy(np.asarray(dataset.obj.fps_points, np.float64)).to(device)

    def __iter__(self) -> Iterator[dict[str, torch.Tensor]]:
        for raw in self.loader:
            moved = {k: v.to(self.device, non_blocking=True) for k, v in raw.items()}
            yield batch_augment.augment_batch(moved, self.pool, self.extent, self.centres)


def cache_loader(
    root: Path, dataset: PoseDataset, sampler: EpochSampler, loader_args: dict, device: torch.device
) -> BatchLoader:
    """The cache path for `dataset` (built under `root` when missing): a DataLoader with `loader_args`
    (workers, pinning, ...) over a CacheDataset, its batches augmented on `device`."""
    folder, _ = open_cache(root, dataset.instances, dataset.cfg)
    cached = CacheDataset(dataset, folder)
    loader = DataLoader(
        cached, batch_size=sampler.batch_size, sampler=sampler, collate_fn=collate, **loader_args
    )
    return BatchLoader(loader, cached, device)
