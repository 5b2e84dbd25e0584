"""The target detector of the paper's protocol: its configuration, the torchvision FCOS network and its data.

One class (the target object) is learned from the visible box `bbox_visib`, since the pose network's
crop should cover what is seen. Both presets build from random init (nothing is downloaded): `cpu` a
small strided-conv backbone with one feature level, `paper` FCOS-ResNet50-FPN.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from torch import nn
from torch.utils.data import Dataset
from torchvision.models.detection import FCOS, fcos_resnet50_fpn
from torchvision.models.detection.anchor_utils import AnchorGenerator

from posenet.config import OptimConfig, override_fields, plain, read_config_file
from posenet.data.augment import brightness_contrast
from posenet.data.layout import Instance, scan_split
from posenet.errors import PosenetError

PRESETS = ("cpu", "paper")
ALIASES = {"smoke": "cpu"}
ARCHS = ("tiny-fcos", "fcos-resnet50-fpn")


@dataclass
class DetectorConfig:
    """Network, input size, augmentations (per-image probabilities) and optimisation of a detector run."""

    preset: str = "paper"
    arch: str = "fcos-resnet50-fpn"
    width: int = 32  # tiny-fcos: channels of the first stage (doubled per stage)
    min_size: int = 800  # images are resized so the short side is min_size (long side <= max_size)
    max_size: int = 1333
    score_thresh: float = 0.05  # detections below are dropped; an image left without any is a miss
    obj_id: int = 1
    color_prob: float = 0.8  # brightness/contrast, as the pose network's (data.augment)
    brightness: tuple[float, float] = (0.5, 1.5)
    contrast: tuple[float, float] = (0.5, 1.5)
    zoom_prob: float = 0.8  # scale: the image zoomed about a random point, the target kept inside
    zoom: tuple[float, float] = (0.6, 1.6)
    workers: int = 2
    optim: OptimConfig = field(
        default_factory=lambda: OptimConfig(lr=1e-3, batch_size=16, epochs=50, warmup_iters=500)
    )

    def model_dict(self) -> dict[str, Any]:
        """What fixes the network's weights layout and inference: saved as the checkpoint's model_config."""
        return {k: getattr(self, k) for k in ("arch", "width", "min_size", "max_size", "score_thresh")}

    def to_dict(self) -> dict[str, Any]:
        return plain(dataclasses.asdict(self))


def cpu_config() -> DetectorConfig:
    """The CPU preset: tiny-fcos at the rendered size of the test datasets (320x240), small batches."""
    return DetectorConfig(
        preset="cpu",
        arch="tiny-fcos",
        width=16,
        min_size=240,
        max_size=320,
        workers=0,
        optim=OptimConfig(lr=1e-3, batch_size=4, epochs=30, warmup_iters=20, weight_decay=1e-4, log_every=1),
    )


def load_detector_config(name_or_path: str, obj_id: int | None = None) -> DetectorConfig:
    """A preset name (cpu, its alias smoke, paper) or a YAML/TOML file (`preset:` plus any field)."""
    name = ALIASES.get(name_or_path, name_or_path)
    if name not in PRESETS and not Path(name_or_path).is_file():
        raise PosenetError(
            f"detector config {name_or_path!r} is neither a preset (cpu, smoke, paper) nor a file"
        )
    raw = {"preset": name} if name in PRESETS else read_config_file(Path(name_or_path))
    cfg = detector_config_from_dict(raw)
    if obj_id is not None:
        cfg.obj_id = obj_id
    return cfg


def detector_config_from_dict(raw: dict[str, Any]) -> DetectorConfig:
    """The named preset, then every given field (a checkpoint's `config` reloads to the same config)."""
    raw = dict(raw)
    name = raw.pop("preset", "paper")
    preset = ALIASES.get(name, name)
    if preset not in PRESETS:
        raise PosenetError(f"detector preset must be one of {', '.join(PRESETS)}, got {name!r}")
    cfg = cpu_config() if preset == "cpu" else DetectorConfig()
    optim = raw.pop("optim", None)
    if optim is not None:
        cfg.optim = override_fields(cfg.optim, optim, "optim")
    cfg = override_fields(cfg, raw, "detector")
    if cfg.arch not in ARCHS:
        raise PosenetError(f"detector arch must be one of {', '.join(ARCHS)}, got {cfg.arch!r}")
    if min(cfg.width, cfg.min_size, cfg.max_size, cfg.optim.batch_size, cfg.optim.epochs) < 1:
        raise PosenetError("detector width, min_size, max_size, optim.batch_size, optim.epochs must be >= 1")
    return cfg


class _TinyBackbone(nn.Sequential):
    """Four stride-2 conv stages (stride 16), the single feature map FCOS predicts from."""

    def __init__(self, width: int) -> None:
        layers: list[nn.Module] = []
        c_in = 3
        for i in range(4):
            c_out = width * 2**i
            layers += [
                nn.Conv2d(c_in, c_out, 3, stride=2, padding=1, bias=False),
                nn.BatchNorm2d(c_out),
                nn.ReLU(inplace=True),
                nn.Conv2d(c_out, c_out, 3, padding=1, bias=False),
                nn.BatchNorm2d(c_out),
                nn.ReLU(inplace=True),
            ]
            c_in = c_out
        super().__init__(*layers)
        self.out_channels = c_in


def build_detector(model_config: dict[str, Any]) -> FCOS:
    """The FCOS network of a `DetectorConfig.model_dict()`, random init (classes: background, target)."""
    kw = {k: model_config[k] for k in ("min_size", "max_size", "score_thresh")} | {"detections_per_img": 10}
    if model_config["arch"] == "fcos-resnet50-fpn":
        model = fcos_resnet50_fpn(weights=None, weights_backbone=None, num_classes=2, **kw)
    else:
        # one level: the anchor size sets the centre-sampling radius (1.5 x 64 px) and the regression unit
        anchors = AnchorGenerator(sizes=((64,),), aspect_ratios=((1.0,),))
        model = FCOS(_TinyBackbone(model_config["width"]), num_classes=2, anchor_generator=anchors, **kw)
    # the box distances pass a ReLU: starting them at 1 anchor size, not 0, keeps half of them from dying
    # at once (from random init with lr 1e-3 every one did, and every box had size 0)
    nn.init.constant_(model.head.regression_head.bbox_reg.bias, 1.0)
    return model


def image_groups(root: Path, split: str, obj_id: int) -> list[list[Instance]]:
    """The split's images that show object `obj_id` in the annotations, each as its list of instances."""
    groups: dict[tuple[int, int], list[Instance]] = {}
    for inst in scan_split(root, split, obj_id):
        groups.setdefault(inst.key, []).append(inst)
    return list(groups.values())


def visible_boxes(instances: list[Instance]) -> np.ndarray:
    """(n, 4) float32 [x0, y0, x1, y1] pixel-edge boxes of the instances with a visible pixel (bbox_visib)."""
    boxes = [(x, y, x + w, y + h) for i in instances if i.px_count_visib > 0 for x, y, w, h in [i.bbox_visib]]
    return np.array(boxes, np.float32).reshape(-1, 4)


def random_zoom(
    img: np.ndarray, boxes: np.ndarray, rng: np.random.Generator, scale: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """The image scaled by s ~ U(scale) on a canvas of its own size (black outside), shifted at random but
    keeping the targets' union box inside where it fits; the boxes moved alike."""
    h, w = img.shape[:2]
    s = rng.uniform(*scale)
    if len(boxes):
        x0, y0 = boxes[:, :2].min(0) * s
        x1, y1 = boxes[:, 2:].max(0) * s
    else:
        x0, y0, x1, y1 = 0.0, 0.0, w * s, h * s
    tx = rng.uniform(-x0, w - x1) if w - x1 >= -x0 else (w - x0 - x1) / 2
    ty = rng.uniform(-y0, h - y1) if h - y1 >= -y0 else (h - y0 - y1) / 2
    out = cv2.warpAffine(img, np.float32([[s, 0, tx], [0, s, ty]]), (w, h), flags=cv2.INTER_LINEAR)
    moved = boxes * s + np.float32([tx, ty, tx, ty])
    moved[:, 0::2] = moved[:, 0::2].clip(0, w)
    moved[:, 1::2] = moved[:, 1::2].clip(0, h)
    return out, moved[(moved[:, 2] - moved[:, 0] >= 1) & (moved[:, 3] - moved[:, 1] >= 1)]


class DetectionDataset(Dataset):
    """One item per image: (3, H, W) float RGB in [0, 1] and its FCOS target {boxes, labels} (bbox_visib).

    With `train`, each image is augmented (brightness/contrast, zoom) from a generator seeded by
    (seed, epoch, index): the same run sees the same images, whatever the loader processes.
    """

    def __init__(self, images: list[list[Instance]], cfg: DetectorConfig, train: bool, seed: int = 0) -> None:
        self.images, self.cfg, self.train, self.seed, self.epoch = images, cfg, train, seed, 0

    def __len__(self) -> int:
        return len(self.images)

    def __getitem__(self, index: int) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        insts = self.images[index]
        img = cv2.cvtColor(cv2.imread(str(insts[0].rgb), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        img = img.astype(np.float32) / 255
        boxes = visible_boxes(insts)
        if self.train:
            rng = np.random.default_rng([self.seed, self.epoch, index])
            c = self.cfg
            if rng.random() < c.zoom_prob:
                img, boxes = random_zoom(img, boxes, rng, c.zoom)
            if rng.random() < c.color_prob:
                img = brightness_contrast(img, rng, c.brightness, c.contrast)
        target = {"boxes": torch.from_numpy(boxes), "labels": torch.ones(len(boxes), dtype=torch.int64)}
        return torch.from_numpy(np.ascontiguousarray(img.transpose(2, 0, 1))), target


def collate(batch: list[tuple[torch.Tensor, dict]]) -> tuple[list[torch.Tensor], list[dict]]:
    """Lists of images and targets, as torchvision's detection models take them."""
    return [b[0] for b in batch], [b[1] for b in batch]
