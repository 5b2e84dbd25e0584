"""Running a trained detector: its checkpoint, one box per image, and the box metrics (IoU, AP50, misses).

A detection is the highest-scoring box of an image (of one object: `Detection.of`); an image with none
above the score threshold is a miss (None). Every box the detector kept rides along with its obj_id
(`Detection.found`). Boxes are [x0, y0, x1, y1] pixel edges, the convention of `detector.visible_boxes`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor
from torch.utils.data import DataLoader
from torchvision.models.detection import FCOS
from torchvision.models.detection.image_list import ImageList
from torchvision.models.detection.transform import resize_boxes
from torchvision.ops.boxes import clip_boxes_to_image
from tqdm import tqdm

from posenet.checkpoint import load_checkpoint
from posenet.data.boxes import edges_box, miss_entry
from posenet.data.layout import Instance
from posenet.detection.detector import (
    DetectionDataset,
    build_detector,
    collate,
    detector_config_from_dict,
    image_groups,
    target_boxes,
    visible_boxes,
)
from posenet.detection.segmenter import MaskDetector, mask_box

EdgeBox = tuple[float, float, float, float]  # [x0, y0, x1, y1] pixel edges


@dataclass(frozen=True)
class Found:
    """One box the detector kept in an image: its edges, score and the object (obj_id) of its class."""

    box: EdgeBox
    score: float
    obj_id: int


@dataclass(frozen=True)
class Detection:
    """The detector's answer for one image: its best box and score (box None: a miss), the seconds
    of its forward, and every box it kept, best first."""

    key: tuple[int, int]  # (scene_id, im_id)
    box: EdgeBox | None
    score: float
    time_s: float
    found: tuple[Found, ...] = ()

    def of(self, obj_id: int) -> Detection:
        """The image's detection of object `obj_id` alone: its best box of that class, or a miss."""
        mine = tuple(f for f in self.found if f.obj_id == obj_id)
        box, score = (mine[0].box, mine[0].score) if mine else (None, 0.0)
        return Detection(self.key, box, score, self.time_s, mine)


def detector_obj_ids(state: dict[str, Any]) -> list[int]:
    """A detector checkpoint's classes: the obj_id of each (class k + 1 is the k-th); a checkpoint from
    before several objects, one class, its config's obj_id."""
    return list(state.get("obj_ids") or [int(state["config"].get("obj_id", 1))])


def load_detector(ckpt: Path, device: torch.device) -> tuple[FCOS, dict[str, Any]]:
    """The network of a detector checkpoint, in eval mode on `device`, and the checkpoint itself."""
    state = load_checkpoint(ckpt, kind="detector")
    model = build_detector(state["model_config"], classes=len(detector_obj_ids(state)))
    model.load_state_dict(state["model"])
    return model.to(device).eval(), state


def found_boxes(pred: dict[str, Tensor], obj_ids: list[int]) -> tuple[Found, ...]:
    """A torchvision-style detector's output for one image ({boxes, scores, labels}) as its boxes, best
    first, each with the obj_id of its label (label k: obj_ids[k - 1])."""
    order = pred["scores"].argsort(descending=True).tolist()
    boxes, scores, labels = (pred[k].detach().cpu() for k in ("boxes", "scores", "labels"))
    return tuple(
        Found(tuple(float(v) for v in boxes[i]), float(scores[i]), obj_ids[int(labels[i]) - 1])  # type: ignore[arg-type]
        for i in order
    )


@torch.inference_mode()
def detect(model: FCOS, dataset: DetectionDataset, device: torch.device) -> list[Detection]:
    """The best box of each image of the dataset, one image per forward (the batch-1 latency is its time),
    with every box kept labelled by the dataset configuration's classes."""
    model.eval()
    obj_ids = dataset.cfg.classes()
    out = []
    loader = DataLoader(dataset, batch_size=1, collate_fn=collate)
    for i, (images, _) in enumerate(tqdm(loader, desc="detect", unit="img", dynamic_ncols=True, leave=False)):
        tic = time.perf_counter()
        pred = model([im.to(device) for im in images])[0]
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        toc = time.perf_counter() - tic
        key = dataset.images[i][0].key
        found = found_boxes(pred, obj_ids)
        if not found:
            out.append(Detection(key, None, 0.0, toc))
        else:
            out.append(Detection(key, found[0].box, found[0].score, toc, found))
    return out


def fcos_best_box(fcos: FCOS, head: dict[str, Tensor], anchors: Tensor) -> tuple[Tensor, Tensor]:
    """Each image's best-scoring box ([x0, y0, x1, y1] in the network's resized image, B x 4) and its score
    (B) from FCOS's head outputs over `anchors`: the score is FCOS's sqrt(class x centre-ness), and the best
    one is the box its NMS keeps first, so this is the full detector's first detection, at fixed shapes."""
    scores = torch.sqrt(torch.sigmoid(head["cls_logits"]) * torch.sigmoid(head["bbox_ctrness"]))
    best_score, best = scores.flatten(1).max(1)
    anchor = best // scores.shape[-1]
    rows = torch.arange(len(best), device=best.device)
    return fcos.box_coder.decode(head["bbox_regression"][rows, anchor], anchors[anchor]), best_score


class BatchBestBox:
    """The best box of each image of a batch at fixed shapes, for predict's batched path: `prepare` (FCOS's
    own transform: normalise, resize, pad), then `run`, the fixed-shape part a caller may capture as one
    CUDA graph (FCOS's backbone and head and an argmax over its scores, which is the box its NMS keeps
    first, as posenet.export.onnx_export.DetectorBestBox; a mask detector's probabilities), then `boxes`.
    Equal to the full detector's first detection per image (tests/test_posenet_predict.py)."""

    def __init__(self, model: FCOS | MaskDetector) -> None:
        self.model = model.eval()
        self._anchors: dict[tuple[int, ...], Tensor] = {}  # per input shape: made once, outside a capture
        self._sizes: tuple[tuple[int, int], tuple[int, int]] | None = None  # (original, resized) (h, w)

    def prepare(self, images: Tensor) -> Tensor:
        """B x 3 x H x W RGB in [0, 1] -> the network's input."""
        if isinstance(self.model, MaskDetector):
            return images
        batch, _ = self.model.transform(list(images))
        self._sizes = (tuple(images.shape[-2:]), batch.image_sizes[0])
        return batch.tensors

    def run(self, x: Tensor) -> tuple[Tensor, Tensor]:
        """FCOS: the best box ([x0, y0, x1, y1] in the resized image, B x 4) and score (B); a mask detector:
        the target's probability per pixel (B x H x W) and its peak (B)."""
        if isinstance(self.model, MaskDetector):
            prob = torch.sigmoid(self.model.logits(x)[:, 0])
            return prob, prob.flatten(1).amax(1)
        fcos = self.model
        features = list(fcos.backbone(x).values())
        head = {k: v.float() for k, v in fcos.head(features).items()}  # boxes decoded in float32 under bf16
        key = tuple(x.shape[-2:])
        if key not in self._anchors:
            self._anchors[key] = fcos.anchor_generator(ImageList(x[:1], [key]), features)[0]  # type: ignore[list-item]
        anchors = self._anchors[key]
        box, best_score = fcos_best_box(fcos, head, anchors)
        assert self._sizes is not None, "prepare the batch first"
        return clip_boxes_to_image(box, self._sizes[1]), best_score

    def boxes(self, out: tuple[Tensor, Tensor]) -> list[tuple[np.ndarray, float] | None]:
        """Per image: the best [x0, y0, x1, y1] (pixel edges of the input image) and score, or None where
        the detector finds nothing (FCOS: no score over its score_thresh; a mask: mask_box's None)."""
        first, scores = (v.float().cpu() for v in out)
        if isinstance(self.model, MaskDetector):
            return [mask_box(p, self.model.score_thresh) for p in first.numpy()]
        assert self._sizes is not None
        boxes = resize_boxes(first, list(self._sizes[1]), list(self._sizes[0])).double().numpy()
        thresh = self.model.score_thresh
        return [(b, float(s)) if s > thresh else None for b, s in zip(boxes, scores.tolist(), strict=True)]


def detect_split(
    ckpt: Path, data: Path, split: str, obj_id: int, device: torch.device
) -> tuple[list[list[Instance]], list[Detection], dict[str, Any]]:
    """The detector checkpoint run over the split's images that show `obj_id`: those images (each its
    instances), their detections (a detector of several objects: its boxes of `obj_id`), and the
    checkpoint."""
    model, state = load_detector(ckpt, device)
    images = image_groups(data, split, obj_id)
    dets = detect(model, detector_dataset(state, images), device)
    if len(detector_obj_ids(state)) > 1:
        dets = [d.of(obj_id) for d in dets]
    return images, dets, state


def detector_dataset(state: dict[str, Any], images: list) -> DetectionDataset:
    """The evaluation dataset of `images` as the checkpoint's run reads them (no augmentation)."""
    return DetectionDataset(images, detector_config_from_dict(state["config"]), train=False)


def iou(a: tuple[float, ...] | None, b: np.ndarray) -> float:
    """IoU of box `a` (None: 0) with the first box of `b` ((n, 4); an empty `b` gives 0)."""
    if a is None or len(b) == 0:
        return 0.0
    bx = b[0]
    w = max(0.0, min(a[2], bx[2]) - max(a[0], bx[0]))
    h = max(0.0, min(a[3], bx[3]) - max(a[1], bx[1]))
    inter = w * h
    union = (a[2] - a[0]) * (a[3] - a[1]) + (bx[2] - bx[0]) * (bx[3] - bx[1]) - inter
    return float(inter / union) if union > 0 else 0.0


def box_metrics(dets: list[Detection], gt: list[np.ndarray]) -> dict[str, float]:
    """Mean IoU (a miss counts 0), the share of images at IoU >= 0.5, AP50 (single class, all-point
    interpolated; one detection per image) and misses, over images whose target is visible (gt[i]: the
    boxes dets[i] is scored against, empty where the target is not visible)."""
    pairs = [(d, g) for d, g in zip(dets, gt, strict=True) if len(g)]
    ious = [iou(d.box, g) for d, g in pairs]
    order = sorted(
        (i for i, (d, _) in enumerate(pairs) if d.box is not None), key=lambda i: -pairs[i][0].score
    )
    tp = np.array([ious[i] >= 0.5 for i in order], float)
    ap = 0.0
    if len(pairs) and len(tp):
        recall = np.cumsum(tp) / len(pairs)
        precision = np.cumsum(tp) / np.arange(1, len(tp) + 1)
        precision = np.maximum.accumulate(precision[::-1])[::-1]  # the envelope: best precision at >= recall
        ap = float(np.sum(np.diff(np.concatenate([[0.0], recall])) * precision))
    return {
        "n": len(pairs),
        "mean_iou": float(np.mean(ious)) if ious else float("nan"),
        "iou50": float(np.mean([v >= 0.5 for v in ious])) if ious else float("nan"),
        "ap50": ap,
        "misses": sum(d.box is None for d, _ in pairs),
    }


def box_scores(dets: list[Detection], images: list[list[Instance]]) -> dict[str, float]:
    """`box_metrics` of `dets` (one per image of `images`) against the box the detector learns and the
    pose network is cropped around (target_boxes: bbox_obj clipped to the image), with the mean IoU, the
    share at IoU >= 0.5 and AP50 against the visible pixels' box (`visible_boxes`, bbox_visib) beside them
    under `visib_` keys."""
    visib = box_metrics(dets, [visible_boxes(i) for i in images])
    return box_metrics(dets, [target_boxes(i) for i in images]) | {
        f"visib_{k}": visib[k] for k in ("mean_iou", "iou50", "ap50")
    }


def class_box_scores(
    dets: list[Detection], images: list[list[Instance]], obj_ids: list[int]
) -> dict[str, float]:
    """`box_scores` pooled over the objects `obj_ids`: each image showing an object counts once for it,
    its detection that object's best box (`Detection.of`) against that object's instances. With one
    object whose instances alone `images` hold, this is box_scores itself."""
    pairs = [
        (d.of(k), mine)
        for k in obj_ids
        for d, insts in zip(dets, images, strict=True)
        if (mine := [i for i in insts if i.obj_id == k])
    ]
    return box_scores([d for d, _ in pairs], [m for _, m in pairs])


def detection_entries(dets: list[Detection], obj_id: int, source: str) -> list[dict]:
    """The detections as a box file (posenet.data.boxes): [x, y, w, h] pixel boxes, a miss as miss_entry."""
    out = []
    for d in dets:
        if d.box is None:
            out.append(miss_entry(*d.key, obj_id, d.time_s, source))
            continue
        bbox = [round(v, 2) for v in edges_box(d.box)]
        out.append({"scene_id": d.key[0], "image_id": d.key[1], "category_id": obj_id, "bbox": bbox,
                    "score": round(d.score, 4), "time": d.time_s, "source": source})  # fmt: skip
    return out
