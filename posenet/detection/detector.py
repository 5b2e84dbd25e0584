"""The target detector of the paper's protocol: its configuration, its networks and its data.

One class per object (`obj_ids`; by default the target alone, `obj_id`) is learned as the pose network is
cropped: around the whole object's
box (`bbox_obj`, occluded parts included) clipped to the image, the amodal box of GDRNPP's detectors
(`target_boxes`); the mask network learns the whole object's in-image mask (`mask`), whose extent is
that box. `bbox_visib` stays a box a detector is also scored against (`visible_boxes`). The backbone
starts from ImageNet weights, loaded as the pose network's are (`pretrained`, posenet.models.backbone).
Three networks: `fcos-timm-fpn` (the `cpu` and `light` presets) FCOS over the package-shipped
EfficientNet-Lite0 with an FPN over strides 8-32 (the benchmark's targets are mostly 10-64 px);
`fcos-resnet50-fpn` (the `paper` preset) torchvision's FCOS-ResNet50-FPN on timm's ImageNet ResNet-50;
`mask-timm` the object's mask over a timm backbone, its box the mask's extent (posenet.detection.segmenter).
`pretrained: null` trains from random init.
"""

from __future__ import annotations

import dataclasses
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from torch import Tensor, nn
from torch.utils.data import Dataset
from torchvision.models.detection import FCOS, fcos_resnet50_fpn
from torchvision.models.detection.anchor_utils import AnchorGenerator
from torchvision.models.detection.fcos import FCOSHead
from torchvision.ops import FeaturePyramidNetwork

from posenet.config import OptimConfig, override_fields, plain, read_config_file
from posenet.data.augment import brightness_contrast
from posenet.data.boxes import box_edges, clip_box
from posenet.data.io import read_bgr, read_mask
from posenet.data.layout import Instance, scan_split
from posenet.detection.segmenter import MaskDetector
from posenet.errors import PosenetError
from posenet.models.backbone import initial_weights, input_mean_std, timm_features
from posenet.models.config import IMAGENET, PACKAGE

ALIASES = {"smoke": "cpu"}
ARCHS = ("mask-timm", "fcos-timm-fpn", "fcos-resnet50-fpn")
MASK_ARCHS = ("mask-timm",)  # the networks that learn the object's mask (their targets carry masks)
# a resampled 0 / 1 mask is the target's where it reaches this: bilinear resampling spreads a lone or
# diagonal pixel to >= 1/4 about its place but not always to 1/2
MASK_CUT = 0.25
POSE_ONLY_OPTIM = ("amp", "grad_centralization")  # OptimConfig fields only pose training reads
STRIDES = (2, 4, 8, 16, 32)  # the backbone strides fcos-timm-fpn may predict at (min_stride ... 32)
FCOS_NORM_GROUPS = 32  # the GroupNorm groups of torchvision's FCOSHead: fpn_channels must divide by them


@dataclass
class DetectorConfig:
    """Network, input size, augmentations (per-image probabilities) and optimisation of a detector run."""

    preset: str = "paper"
    arch: str = "fcos-resnet50-fpn"
    backbone: str = "tf_efficientnet_lite0"  # mask-timm, fcos-timm-fpn: the timm model
    fpn_channels: int = 64  # mask-timm: the decoder's channels; fcos-timm-fpn: the FPN's and FCOS head's
    min_stride: int = 8  # fcos-timm-fpn: FCOS predicts at the backbone strides min_stride ... 32
    head_convs: int = 4  # fcos-timm-fpn: conv layers of each FCOS head branch
    # where the backbone's weights come from: imagenet | package | a local file | None (random init)
    pretrained: str | None = IMAGENET
    min_size: int = 800  # FCOS resizes images so the short side is min_size (long side <= max_size)
    max_size: int = 1333
    score_thresh: float = 0.05  # detections below are dropped; an image left without any is a miss
    obj_id: int = 1
    # the classes, class k + 1 being obj_ids[k]; empty: `obj_id` alone (one class, as a one-object detector)
    obj_ids: list[int] = field(default_factory=list)
    color_prob: float = 0.8  # brightness/contrast, as the pose network's (data.augment)
    brightness: tuple[float, float] = (0.5, 1.5)
    contrast: tuple[float, float] = (0.5, 1.5)
    zoom_prob: float = 0.8  # scale: the image zoomed about a random point, the target kept inside
    zoom: tuple[float, float] = (0.6, 1.6)
    flip_prob: float = 0.5  # horizontal mirror
    paste_prob: float = 0.5  # copy-paste: the visible target of another training image pasted in as well
    workers: int = 2
    optim: OptimConfig = field(
        default_factory=lambda: OptimConfig(lr=1e-3, batch_size=16, epochs=50, warmup_iters=500)
    )

    def model_dict(self) -> dict[str, Any]:
        """What fixes the network's weights layout and inference: saved as the checkpoint's model_config."""
        keys = ["arch", "backbone", "fpn_channels", "min_stride", "head_convs"]
        keys += ["min_size", "max_size", "score_thresh"]
        return {k: getattr(self, k) for k in keys}

    def to_dict(self) -> dict[str, Any]:
        return plain(dataclasses.asdict(self))

    def classes(self) -> list[int]:
        """The obj_id of each class (FCOS's label k is classes()[k - 1]; label 0 is the background)."""
        return list(self.obj_ids) if self.obj_ids else [self.obj_id]


def cpu_config() -> DetectorConfig:
    """The CPU preset: FCOS on the package-shipped ImageNet EfficientNet-Lite0 + FPN at the rendered size
    of the test datasets (320x240)."""
    return DetectorConfig(
        preset="cpu",
        arch="fcos-timm-fpn",
        pretrained=PACKAGE,
        min_size=240,
        max_size=320,
        workers=0,
        # lr 1e-3, not the 3e-3 random init wanted: the ImageNet features are to be tuned, not relearned
        optim=OptimConfig(lr=1e-3, batch_size=4, epochs=18, warmup_iters=20, weight_decay=1e-4, log_every=1),
    )


def light_config() -> DetectorConfig:
    """The CPU preset at half its input side (160x120) with two conv layers in each head branch instead
    of four: for frame rate. Trained the same 12 minutes on the control set it took 30-32 against 75-96
    ms an image in torch and 12.5 against 30 ms in onnxruntime on 2 cores, scored a mean IoU of 0.737
    against 0.716 on its own box, and gave the pose network 40.0 against 42.5 % ADD@0.1d on 360 held-out
    images, a difference those images cannot tell (McNemar p = 0.26; docs/benchmarks.md)."""
    return dataclasses.replace(cpu_config(), preset="light", min_size=120, max_size=160, head_convs=2)


PRESET_CONFIGS = {"cpu": cpu_config, "light": light_config, "paper": DetectorConfig}
PRESETS = tuple(PRESET_CONFIGS)


def load_detector_config(
    name_or_path: str, obj_id: int | None = None, dataset_ids: list[int] | None = None
) -> DetectorConfig:
    """A preset name (cpu, its alias smoke, light, paper) or a YAML/TOML file (`preset:` plus any field).
    `obj_id` learns that object alone (one class); without it, a config naming neither `obj_id` nor
    `obj_ids` learns every object of `dataset_ids` (the dataset's models_info) when there are several (an
    FCOS; the mask network learns one object)."""
    name = ALIASES.get(name_or_path, name_or_path)
    if name not in PRESETS and not Path(name_or_path).is_file():
        raise PosenetError(
            f"detector config {name_or_path!r} is neither a preset (cpu, smoke, light, paper) nor a file"
        )
    raw = {"preset": name} if name in PRESETS else read_config_file(Path(name_or_path))
    cfg = detector_config_from_dict(raw)
    if obj_id is not None:
        cfg.obj_id, cfg.obj_ids = obj_id, []
    elif len(dataset_ids or ()) > 1 and cfg.arch not in MASK_ARCHS and not {"obj_id", "obj_ids"} & raw.keys():
        cfg.obj_ids = sorted(dataset_ids)
    return cfg


def detector_config_from_dict(raw: dict[str, Any]) -> DetectorConfig:
    """The named preset, then every given field (a checkpoint's `config` reloads to the same config)."""
    raw = dict(raw)
    name = raw.pop("preset", "paper")
    preset = ALIASES.get(name, name)
    if preset not in PRESETS:
        raise PosenetError(f"detector preset must be one of {', '.join(PRESETS)}, got {name!r}")
    cfg = PRESET_CONFIGS[preset]()
    optim = raw.pop("optim", None)
    if optim is not None:
        changed = [k for k in POSE_ONLY_OPTIM if k in optim and optim[k] != getattr(OptimConfig(), k)]
        if changed:
            raise PosenetError(f"optim.{changed[0]} is a pose-training option, not the detector's")
        cfg.optim = override_fields(cfg.optim, optim, "optim")
    cfg = override_fields(cfg, raw, "detector")
    if cfg.arch not in ARCHS:
        raise PosenetError(f"detector arch must be one of {', '.join(ARCHS)}, got {cfg.arch!r}")
    sizes = {k: getattr(cfg, k) for k in ("fpn_channels", "head_convs", "min_size", "max_size")}
    sizes |= {f"optim.{k}": getattr(cfg.optim, k) for k in ("batch_size", "epochs")}
    for name, value in sizes.items():
        if value < 1:
            raise PosenetError(f"detector {name} must be >= 1, got {value}")
    if cfg.arch == "fcos-timm-fpn" and cfg.fpn_channels % FCOS_NORM_GROUPS:  # FCOS's GroupNorm: 32 groups
        raise PosenetError(
            f"detector fpn_channels must be a multiple of {FCOS_NORM_GROUPS}, got {cfg.fpn_channels}"
        )
    if cfg.min_stride not in STRIDES:
        raise PosenetError(f"detector min_stride must be one of {list(STRIDES)}, got {cfg.min_stride}")
    ids = cfg.classes()
    if not all(isinstance(k, int) and not isinstance(k, bool) and k >= 1 for k in ids) or len(set(ids)) < len(
        ids
    ):
        raise PosenetError(f"detector obj_ids must be distinct obj_ids (integers >= 1), got {ids}")
    if cfg.arch in MASK_ARCHS and len(cfg.classes()) > 1:
        raise PosenetError(f"{cfg.arch} learns one object's mask: give it one object (--obj-id)")
    return cfg


class TimmFpn(nn.Module):
    """A timm backbone's maps at `strides` through torchvision's FPN: the levels FCOS predicts from."""

    def __init__(self, name: str, channels: int, strides: list[int], pretrained: str | None = None) -> None:
        super().__init__()
        self.body = timm_features(name, pretrained, (0, 1, 2, 3, 4))
        reductions = self.body.feature_info.reduction()
        if not set(strides) <= set(reductions):
            raise PosenetError(f"detector strides {strides} are not among {name}'s {reductions}")
        self.levels = [reductions.index(s) for s in strides]
        self.fpn = FeaturePyramidNetwork(
            [self.body.feature_info.channels()[i] for i in self.levels], channels
        )
        self.out_channels = channels

    def forward(self, x: Tensor) -> OrderedDict[str, Tensor]:
        maps = self.body(x)
        return self.fpn(OrderedDict((str(i), maps[i]) for i in self.levels))


def build_detector(
    model_config: dict[str, Any], pretrained: str | None = None, classes: int = 1
) -> FCOS | MaskDetector:
    """The network of a `DetectorConfig.model_dict()` (FCOS: the background and `classes` objects), its
    backbone initialised from `pretrained` (posenet.models.backbone) or random init. Images are normalised
    as the backbone's ImageNet weights expect (timm's pretrained_cfg mean / std)."""
    if model_config["arch"] in MASK_ARCHS:
        return MaskDetector(
            model_config["backbone"], model_config["fpn_channels"], model_config["score_thresh"], pretrained
        )
    kw = {k: model_config[k] for k in ("min_size", "max_size", "score_thresh")} | {"detections_per_img": 10}
    num_classes = classes + 1
    if model_config["arch"] == "fcos-resnet50-fpn":
        model = fcos_resnet50_fpn(weights=None, weights_backbone=None, num_classes=num_classes, **kw)
        weights = initial_weights("resnet50", pretrained)
        if weights is not None:  # timm and torchvision share ResNet keys; FCOS has no classifier
            model.backbone.body.load_state_dict({k: v for k, v in weights.items() if not k.startswith("fc.")})
    else:
        # one anchor per location, its size the level's stride: FCOS then assigns a box to the level
        # whose [4, 8] x stride range holds its largest side distance, and samples centres within 1.5 strides
        strides = [s for s in STRIDES if s >= model_config["min_stride"]]
        anchors = AnchorGenerator(sizes=tuple((s,) for s in strides), aspect_ratios=((1.0,),) * len(strides))
        channels = model_config["fpn_channels"]
        backbone = TimmFpn(model_config["backbone"], channels, strides, pretrained)
        head = FCOSHead(channels, 1, num_classes, num_convs=model_config["head_convs"])
        mean, std = input_mean_std(backbone.body)
        model = FCOS(backbone, num_classes=num_classes, anchor_generator=anchors, head=head, **kw,
                     image_mean=list(mean), image_std=list(std))  # fmt: skip
    # the box distances pass a ReLU: starting them at 1 anchor size, not 0, keeps half of them from dying
    # at once (from random init with lr 1e-3 every one did, and every box had size 0)
    nn.init.constant_(model.head.regression_head.bbox_reg.bias, 1.0)
    return model


def image_groups(root: Path, split: str, obj_id: int | Sequence[int]) -> list[list[Instance]]:
    """The split's images that show object `obj_id` (or any of several) in the annotations, each as its
    list of instances in annotation order."""
    ids = [obj_id] if isinstance(obj_id, int) else list(obj_id)
    found = [inst for k in ids for inst in scan_split(root, split, k)]
    groups: dict[tuple[int, int], list[Instance]] = {}
    for inst in sorted(found, key=lambda i: (i.key, i.inst)):
        groups.setdefault(inst.key, []).append(inst)
    return list(groups.values())


def _learned(instances: list[Instance]) -> list[tuple[Instance, Any]]:
    """The instances with a visible pixel whose whole-object box (bbox_obj) clipped to the image
    (posenet.data.boxes.clip_box) is not empty, each with that box."""
    clipped = [(i, clip_box(i.bbox_obj, i.image_size)) for i in instances if i.px_count_visib > 0]
    return [(i, box) for i, box in clipped if box is not None]


def target_boxes(instances: list[Instance]) -> np.ndarray:
    """(n, 4) float32 [x0, y0, x1, y1] pixel-edge boxes the detector learns: of the instances with a visible
    pixel, the whole object's box (bbox_obj) clipped to the image (posenet.data.boxes.clip_box)."""
    return np.array([box_edges(box) for _, box in _learned(instances)], np.float32).reshape(-1, 4)


def labelled_boxes(instances: list[Instance], classes: list[int]) -> np.ndarray:
    """(n, 5) float32: `target_boxes` with each box's class label (1 + its obj_id's place in `classes`)."""
    rows = [[*box_edges(box), classes.index(i.obj_id) + 1] for i, box in _learned(instances)]
    return np.array(rows, np.float32).reshape(-1, 5)


def visible_boxes(instances: list[Instance]) -> np.ndarray:
    """(n, 4) float32 [x0, y0, x1, y1] pixel-edge boxes of the instances with a visible pixel (bbox_visib)."""
    boxes = [box_edges(i.bbox_visib) for i in instances if i.px_count_visib > 0]
    return np.array(boxes, np.float32).reshape(-1, 4)


def random_zoom(
    img: np.ndarray, boxes: np.ndarray, rng: np.random.Generator, scale: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """The image (any channels: a mask may ride along) scaled by s ~ U(scale) on a canvas of its own size
    (black outside), shifted at random but keeping the targets' union box inside where it fits; the boxes
    moved alike (columns after their 4 edges, such as a label, kept)."""
    h, w = img.shape[:2]
    s = rng.uniform(*scale)
    if len(boxes):
        x0, y0 = boxes[:, :2].min(0) * s
        x1, y1 = boxes[:, 2:4].max(0) * s
    else:
        x0, y0, x1, y1 = 0.0, 0.0, w * s, h * s
    tx = rng.uniform(-x0, w - x1) if w - x1 >= -x0 else (w - x0 - x1) / 2
    ty = rng.uniform(-y0, h - y1) if h - y1 >= -y0 else (h - y0 - y1) / 2
    out = cv2.warpAffine(img, np.float32([[s, 0, tx], [0, s, ty]]), (w, h), flags=cv2.INTER_LINEAR)
    out = out.reshape(img.shape)  # cv2 drops a single channel's axis
    moved = boxes.copy()  # any columns after the 4 edges (a label) ride along
    moved[:, :4] = boxes[:, :4] * s + np.float32([tx, ty, tx, ty])
    moved[:, 0:4:2] = moved[:, 0:4:2].clip(0, w)
    moved[:, 1:4:2] = moved[:, 1:4:2].clip(0, h)
    return out, moved[(moved[:, 2] - moved[:, 0] >= 1) & (moved[:, 3] - moved[:, 1] >= 1)]


def _read_rgb(path: Path) -> np.ndarray:
    """An image as float32 RGB in [0, 1]."""
    return cv2.cvtColor(read_bgr(path), cv2.COLOR_BGR2RGB).astype(np.float32) / 255


def paste_target(
    img: np.ndarray,
    boxes: np.ndarray,
    donor: list[Instance],
    rng: np.random.Generator,
    scale: tuple[float, float],
    tries: int = 10,
) -> tuple[np.ndarray, np.ndarray]:
    """Copy-paste: the pixels of the donor's first visible instance's whole-object mask (`mask`: what
    hides the target moves with it), scaled by s ~ U(scale), pasted at a random place clear of `boxes`;
    its box appended (and, when `img` carries a mask as a 4th channel, its mask). Columns of `boxes` after
    the 4 edges are the appended row's 0 (a caller labels it, `DetectionDataset`). Unchanged when the donor
    shows nothing or no clear place is found in `tries`."""
    shown = [i for i in donor if i.px_count_visib > 0]
    if not shown:
        return img, boxes
    found = target_boxes(shown[:1])
    if not len(found):
        return img, boxes
    x0, y0, x1, y1 = (int(v) for v in found[0])
    mask = read_mask(shown[0].mask)[y0:y1, x0:x1] > 0
    patch, s = _read_rgb(shown[0].rgb)[y0:y1, x0:x1], rng.uniform(*scale)
    if img.shape[2] == 4:
        patch = np.dstack([patch, mask.astype(np.float32)])  # its blend is replaced below
    h, w = img.shape[:2]
    size = (max(1, round(patch.shape[1] * s)), max(1, round(patch.shape[0] * s)))
    if size[0] >= w or size[1] >= h:
        return img, boxes
    patch = cv2.resize(patch, size, interpolation=cv2.INTER_LINEAR)
    alpha = cv2.resize(mask.astype(np.float32), size, interpolation=cv2.INTER_LINEAR)[..., None]
    for _ in range(tries):
        px, py = int(rng.integers(w - size[0] + 1)), int(rng.integers(h - size[1] + 1))
        new = np.float32([px, py, px + size[0], py + size[1]])
        clear = (
            (new[2] <= boxes[:, 0])
            | (new[0] >= boxes[:, 2])
            | (new[3] <= boxes[:, 1])
            | (new[1] >= boxes[:, 3])
        )
        if clear.all():
            out = img.copy()
            region = out[py : py + size[1], px : px + size[0]]
            region[:] = alpha * patch + (1 - alpha) * region
            if img.shape[2] == 4:  # the mask stays 0 / 1: one interpolation (the zoom's) before the cut
                region[..., 3] = np.maximum(
                    img[py : py + size[1], px : px + size[0], 3], alpha[..., 0] >= MASK_CUT
                )
            row = np.zeros((1, boxes.shape[1]), np.float32)
            row[0, :4] = new
            return out, np.concatenate([boxes, row])
    return img, boxes


def hflip(img: np.ndarray, boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The image (any channels) mirrored left-right and its [x0, y0, x1, y1] pixel-edge boxes alike."""
    w = img.shape[1]
    out = boxes.copy()  # any columns after the 4 edges (a label) ride along
    out[:, 0], out[:, 2] = w - boxes[:, 2], w - boxes[:, 0]
    return img[:, ::-1], out


class DetectionDataset(Dataset):
    """One item per image: (3, H, W) float RGB in [0, 1] and its target {boxes, labels} (labelled_boxes), plus
    `masks` ((1, H, W) float 0/1, the union of the instances' whole-object masks) for a mask network.

    With `train`, each image is augmented (copy-paste, zoom, mirror, brightness/contrast) from a generator
    seeded by (seed, epoch, index), the index being an (epoch, index) pair from EpochSampler: the same run
    sees the same images, whatever the loader processes. The mask travels through the geometric
    augmentations as a 4th channel of the image.
    """

    def __init__(self, images: list[list[Instance]], cfg: DetectorConfig, train: bool, seed: int = 0) -> None:
        self.images, self.cfg, self.train, self.seed = images, cfg, train, seed

    def __len__(self) -> int:
        return len(self.images)

    def __getitem__(self, index: int | tuple[int, int]) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        epoch, index = index if isinstance(index, tuple) else (0, index)  # EpochSampler's (epoch, index)
        insts = self.images[index]
        img = _read_rgb(insts[0].rgb)
        classes = self.cfg.classes()
        boxes = labelled_boxes(insts, classes)
        with_mask = self.cfg.arch in MASK_ARCHS
        if with_mask:
            shown = [read_mask(i.mask) > 0 for i in insts if i.px_count_visib > 0]
            union = np.logical_or.reduce(shown) if shown else np.zeros(img.shape[:2], bool)
            img = np.dstack([img, union.astype(np.float32)])
        if self.train:
            rng = np.random.default_rng([self.seed, epoch, index])
            c = self.cfg
            if rng.random() < c.paste_prob:
                donor = self.images[int(rng.integers(len(self.images)))]
                before = len(boxes)
                img, boxes = paste_target(img, boxes, donor, rng, c.zoom)
                if len(boxes) > before:  # the donor's first visible instance, as paste_target takes it
                    shown = next(i for i in donor if i.px_count_visib > 0)
                    boxes[-1, 4] = classes.index(shown.obj_id) + 1
            if rng.random() < c.zoom_prob:
                img, boxes = random_zoom(img, boxes, rng, c.zoom)
            if rng.random() < c.flip_prob:
                img, boxes = hflip(img, boxes)
            if rng.random() < c.color_prob:
                img[..., :3] = brightness_contrast(img[..., :3], rng, c.brightness, c.contrast)
        labels = torch.from_numpy(boxes[:, 4].astype(np.int64))
        target = {"boxes": torch.from_numpy(np.ascontiguousarray(boxes[:, :4])), "labels": labels}
        if with_mask:
            target["masks"] = torch.from_numpy((img[None, ..., 3] >= MASK_CUT).astype(np.float32))
        return torch.from_numpy(np.ascontiguousarray(img[..., :3].transpose(2, 0, 1))), target


def collate(batch: list[tuple[torch.Tensor, dict]]) -> tuple[list[torch.Tensor], list[dict]]:
    """Lists of images and targets, as torchvision's detection models take them."""
    return [b[0] for b in batch], [b[1] for b in batch]
