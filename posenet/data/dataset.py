"""The torch Dataset: one RoI sample per instance, with dense targets and augmentations for training.

Items are dicts of tensors. Always: roi_img (3 x R x R, RGB in [0, 1]), roi_coord2d (2 x r x r), K, R, t
(egocentric GT, metres), crop_center, box_wh, resize_ratio (= r / crop side, for SITE), key
(scene_id, im_id). Training adds roi_xyz (3 x r x r, xyz / extent + 0.5), roi_mask_visib, roi_mask_full
(1 x r x r), roi_region (r x r, 0 = background, 1..N = nearest surface-region centre) and site
(dx, dy, z_ratio). Targets are cropped from the full-resolution maps with nearest interpolation.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from posenet.config import DataConfig
from posenet.data import augment
from posenet.data.boxes import Box, read_boxes
from posenet.data.crop import Roi, box_in_roi, crop, roi_coord2d, roi_from_box
from posenet.data.io import read_bgr, read_mask, read_xyz
from posenet.data.layout import Instance, scan_split
from posenet.data.object_model import ObjectModel, load_object_model
from posenet.errors import PosenetError
from posenet.geometry import site_encode
from posenet.models import ModelConfig


def region_labels(xyz: np.ndarray, visible: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Per-pixel surface region: 1 + index of the nearest centre (metres), 0 where not visible."""
    labels = np.zeros(visible.shape, dtype=np.int64)
    pts = xyz[visible > 0]
    if len(pts):
        d2 = ((pts[:, None, :] - centres[None, :, :]) ** 2).sum(-1)
        labels[visible > 0] = d2.argmin(1) + 1
    return labels


def roi_image(bgr: np.ndarray, roi: Roi, res: int) -> np.ndarray:
    """The res x res RoI of a BGR uint8 image as RGB float32 in [0, 1] (training, eval and predict)."""
    return crop(bgr, roi, res, nearest=False)[..., ::-1].astype(np.float32) / 255.0


def image_tensor(img: np.ndarray) -> torch.Tensor:
    """H x W x 3 -> 3 x H x W, contiguous."""
    return torch.from_numpy(np.ascontiguousarray(img.transpose(2, 0, 1)))


def roi_geometry(
    roi: Roi, K: np.ndarray, image_size: tuple[int, int], output_res: int
) -> dict[str, torch.Tensor]:
    """What the network and pose decoding read of a RoI besides its pixels: roi_coord2d, K, crop_center,
    box_wh and resize_ratio (the one home of these items' conventions: training, eval and predict)."""
    return {
        "roi_coord2d": torch.from_numpy(roi_coord2d(roi, output_res, image_size)),
        "K": torch.from_numpy(np.asarray(K, np.float64)).float(),
        "crop_center": torch.from_numpy(roi.center).float(),
        "box_wh": torch.from_numpy(roi.box_wh).float(),
        "resize_ratio": torch.tensor(output_res / roi.scale, dtype=torch.float32),
    }


class PoseDataset(Dataset):
    """RoI samples of `instances`. With `train`, items carry targets and are augmented; each sample's
    randomness comes from (seed, epoch, index), the index being an (epoch, index) pair from EpochSampler.
    `boxes` replaces the GT full-object box by a stored detection box (evaluation protocol).
    """

    def __init__(
        self,
        instances: Sequence[Instance],
        obj: ObjectModel,
        cfg: DataConfig,
        input_res: int,
        output_res: int,
        train: bool,
        boxes: dict[tuple[int, int], Box] | None = None,
        seed: int = 0,
    ) -> None:
        if not instances:
            raise PosenetError("no instances to load (empty split, or every target filtered out)")
        if boxes is not None:
            missing = [i.key for i in instances if i.key not in boxes]
            if missing:
                raise PosenetError(
                    f"box file has no box for {len(missing)} image(s), e.g. (scene, image) {missing[0]}"
                )
        self.instances = list(instances)
        self.obj, self.cfg, self.train, self.boxes, self.seed = obj, cfg, train, boxes, seed
        self.input_res, self.output_res = input_res, output_res
        self._bg_pool: list[np.ndarray] | None = None  # built lazily in each loader process

    def __len__(self) -> int:
        return len(self.instances)

    def __getitem__(self, index: int | tuple[int, int]) -> dict[str, torch.Tensor]:
        epoch, idx = index if isinstance(index, tuple) else (0, index)
        inst = self.instances[idx]
        rng = np.random.default_rng([self.seed, epoch, idx]) if self.train else None
        roi = self._roi(inst, rng)
        # full-resolution full and visible masks: each file is read once per item
        full, visib = (read_mask(inst.mask), read_mask(inst.mask_visib)) if self.train else (None, None)
        roi_img, cut = self._roi_image(inst, roi, rng, visib)
        item = {
            "roi_img": roi_img,
            **roi_geometry(roi, inst.K, inst.image_size, self.output_res),
            "R": torch.from_numpy(inst.R).float(),
            "t": torch.from_numpy(inst.t).float(),
            "key": torch.tensor(inst.key),
        }
        if full is not None and visib is not None:
            item.update(self._targets(inst, roi, full, visib, cut))
            item["site"] = site_encode(
                item["t"], item["K"], item["crop_center"], item["box_wh"], item["resize_ratio"]
            )
        return item

    def _roi(self, inst: Instance, rng: np.random.Generator | None) -> Roi:
        bbox = self.boxes[inst.key] if self.boxes is not None else inst.bbox_obj
        jitter = (
            (self.cfg.dzi_scale, self.cfg.dzi_shift)
            if rng is not None and rng.random() < self.cfg.dzi_prob
            else None
        )
        return roi_from_box(bbox, inst.image_size, self.cfg.pad_scale, jitter, rng)

    def _roi_image(
        self, inst: Instance, roi: Roi, rng: np.random.Generator | None, visib: np.ndarray | None
    ) -> tuple[torch.Tensor, augment.Cut | None]:
        """The RoI crop, augmented when `rng` is given (`visib` is the full-resolution visible mask), and
        the foreground truncation's cut (data.truncate_fg), which the targets follow."""
        img = roi_image(read_bgr(inst.rgb), roi, self.input_res)
        cut = None
        if rng is not None and visib is not None and rng.random() < self.cfg.bg_prob:
            # keep only the visible target, as GDR-Net does: keeping the full mask would keep the part of
            # an occluder that covers the target, whose edge would trace the target's hidden outline
            keep = crop(visib, roi, self.input_res, nearest=True)
            if self.cfg.truncate_fg:
                cut = augment.draw_cut(keep, rng)
                keep = augment.apply_cut(keep, cut)
            img = augment.replace_background(img, keep, self._background(rng))
        if rng is not None:
            img = self._photometric(img, inst, roi, rng)
        return image_tensor(img), cut

    def _photometric(self, img: np.ndarray, inst: Instance, roi: Roi, rng: np.random.Generator) -> np.ndarray:
        """data.augment's colour chain: the paper's brightness/contrast or GDR-Net's chain with probability
        color_prob, or SPNv2's (each of its transforms at p 0.5)."""
        name = self.cfg.augment
        if name == "spnv2" or rng.random() < self.cfg.color_prob:
            if name == "paper":
                return augment.brightness_contrast(img, rng, self.cfg.brightness, self.cfg.contrast)
            from posenet.data.photometric import photometric  # albumentations: imported when asked for

            return photometric(name, img, box_in_roi(inst.bbox_obj, roi), rng)
        return img

    def _background(self, rng: np.random.Generator) -> np.ndarray:
        if rng.random() >= self.cfg.bg_from_dataset or self.cfg.bg_pool_size == 0:
            return augment.noise_background(self.input_res, rng)
        if self._bg_pool is None:
            self._bg_pool = [self._target_free(i) for i in self.bg_pool_instances()]
        return augment.random_view(self._bg_pool[int(rng.integers(len(self._bg_pool)))], self.input_res, rng)

    def bg_pool_instances(self) -> list[Instance]:
        """The instances whose target-free images make the background pool (data.bg_pool_size of them, a
        fixed choice per seed): the per-sample path's pool and the cache path's (posenet.data.cache)."""
        pick = np.random.default_rng(self.seed).permutation(len(self.instances))[: self.cfg.bg_pool_size]
        return [self.instances[i] for i in sorted(pick)]

    @staticmethod
    def _target_free(inst: Instance) -> np.ndarray:
        return augment.paint_out(read_bgr(inst.rgb)[..., ::-1].copy(), read_mask(inst.mask))

    def _targets(
        self, inst: Instance, roi: Roi, full_mask: np.ndarray, visib_mask: np.ndarray, cut: augment.Cut | None
    ) -> dict[str, torch.Tensor]:
        """Dense training targets at output resolution from the full-resolution masks and the xyz map; the
        visible mask (and with it xyz and regions) without what a foreground truncation `cut` away."""
        r = self.output_res
        x0, y0 = inst.xyz_box[:2]
        xyz = crop(read_xyz(inst.xyz), roi, r, nearest=True, offset=(x0, y0))
        visib = augment.apply_cut(crop(visib_mask, roi, r, nearest=True), cut)
        full = crop(full_mask, roi, r, nearest=True)
        xyz_n = np.where(visib[..., None] > 0, xyz / self.obj.extent + 0.5, 0.0).astype(np.float32)
        return {
            "roi_xyz": torch.from_numpy(np.ascontiguousarray(xyz_n.transpose(2, 0, 1))),
            "roi_mask_visib": torch.from_numpy(visib[None].astype(np.float32)),
            "roi_mask_full": torch.from_numpy(full[None].astype(np.float32)),
            "roi_region": torch.from_numpy(region_labels(xyz, visib, self.obj.fps_points)),
        }


SUBSET_ORDER_SEED = 0  # data.train_images' fixed order: the same subsets whatever the training seed


def first_images(instances: Sequence[Instance], n: int) -> list[Instance]:
    """The instances of the first `n` images (by id) in a fixed shuffled order of those `instances` hold."""
    ids = sorted({i.im_id for i in instances})
    if n > len(ids):
        raise PosenetError(f"data.train_images {n} exceeds the {len(ids)} training images of the split")
    keep = set(np.random.default_rng(SUBSET_ORDER_SEED).permutation(ids)[:n].tolist())
    return [i for i in instances if i.im_id in keep]


def open_split(
    root: Path,
    split: str,
    cfg: DataConfig,
    model_cfg: ModelConfig,
    train: bool,
    boxes_file: Path | None = None,
    image_ids: set[int] | None = None,
    seed: int = 0,
) -> PoseDataset:
    """The Dataset of one split of the dataset folder `root` (every check of the folder happens here).

    Both modes keep every instance with a visible pixel, restricted to `image_ids` when given; training
    also drops instances visible by no more than `min_visib_fract` (GDR-Net's configs use 0.0, or 0.2 for
    YCB-V; 0.3 is GDRNPP's), so with the default 0 it trains on every instance evaluation scores, and
    keeps the instances of `train_images` images only when that is set (first_images).
    """
    obj = load_object_model(root, cfg.obj_id, model_cfg.num_regions, cfg.num_pm_points)
    instances = [i for i in scan_split(root, split, cfg.obj_id) if i.px_count_visib > 0]
    if train:
        instances = [i for i in instances if i.visib_fract > cfg.min_visib_fract]
        missing = [p for i in instances for p in (i.xyz, i.mask, i.mask_visib) if not p.is_file()]
        if missing:
            raise PosenetError(f"missing xyz maps or masks ({len(missing)} file(s)), e.g. {missing[0]}")
    if train and cfg.train_images:
        instances = first_images(instances, cfg.train_images)
    if image_ids is not None:
        instances = [i for i in instances if i.im_id in image_ids]
    boxes = read_boxes(boxes_file, cfg.obj_id) if boxes_file is not None else None
    return PoseDataset(instances, obj, cfg, model_cfg.input_res, model_cfg.output_res, train, boxes, seed)
