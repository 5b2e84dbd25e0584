"""The mask detector: one target per image, found as its mask, its box the mask's extent.

scgen's images hold one target, and the pose network is cropped around the whole object's box
(`bbox_obj`), whose part in the image is the extent of the object's mask (`mask`, occluded pixels
included; posenet.detection.detector.target_boxes). A box regressor (FCOS) has to learn four edge
distances from features strides away; a per-pixel mask puts every edge where the pixels say. The
network is a timm backbone (the package-shipped ImageNet EfficientNet-Lite0 by default) with an FPN-style
top-down decoder down to stride 2 and one logit per pixel, upsampled to the input size; it learns `mask`
(binary cross-entropy plus a soft Dice term, which keeps a 10-pixel target from drowning in a 320x240 image).

The box (`mask_box`) is the extent of the confident pixels of the strongest blob: the probability map is
thresholded, blobs closer than `JOIN_SHARE` of the image diagonal are joined (an occluder that cuts the
target in two leaves one target), and the blob of the largest summed probability wins; its score is its
peak probability. The same function serves torch and onnxruntime, whose graph ends at the probabilities.
"""

from __future__ import annotations

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from posenet.models.backbone import InputNorm, timm_features

MASK_THRESH = 0.5  # a pixel is the target's when its probability passes this (or half the peak, if lower)
JOIN_SHARE = 0.03  # blobs closer than this share of the image diagonal are one target
PRIOR_LOGIT = -4.0  # the untrained mask starts near empty (p 0.02), as a target covers a few % of an image
STRIDE_INDICES = (0, 1, 2, 3, 4)  # timm feature levels: strides 2, 4, 8, 16, 32


def mask_box(prob: np.ndarray, score_thresh: float) -> tuple[np.ndarray, float] | None:
    """[x0, y0, x1, y1] pixel edges (float64) and score of the target in a (H, W) probability map, or None
    when no pixel reaches `score_thresh`."""
    peak = float(prob.max())
    if peak < score_thresh:
        return None
    pixels = prob >= min(MASK_THRESH, peak / 2)
    reach = max(1, round(JOIN_SHARE * float(np.hypot(*prob.shape))))
    joined = cv2.dilate(pixels.astype(np.uint8), np.ones((2 * reach + 1,) * 2, np.uint8))
    count, labels = cv2.connectedComponents(joined, connectivity=8)
    mass = np.bincount(labels[pixels], weights=prob[pixels], minlength=count)
    blob = (labels == int(mass[1:].argmax()) + 1) & pixels
    ys, xs = np.nonzero(blob)
    box = np.array([xs.min(), ys.min(), xs.max() + 1, ys.max() + 1], np.float64)
    return box, float(prob[blob].max())


def mask_losses(logits: Tensor, masks: Tensor) -> dict[str, Tensor]:
    """Binary cross-entropy over every pixel and a soft Dice loss over the images that show the target
    ((B, 1, H, W) logits and 0/1 masks)."""
    bce = F.binary_cross_entropy_with_logits(logits, masks)
    prob, shown = torch.sigmoid(logits).flatten(1), masks.flatten(1).sum(1) > 0
    inter = (prob * masks.flatten(1)).sum(1)
    dice = 1 - (2 * inter + 1) / (prob.sum(1) + masks.flatten(1).sum(1) + 1)
    dice = (dice * shown).sum() / shown.sum().clamp(min=1)  # no branch on the data: no device sync
    return {"mask_bce": bce, "mask_dice": dice}


class MaskDetector(nn.Module):
    """Backbone + top-down decoder -> one mask logit per input pixel. Called as torchvision's detectors
    are: in training `model(images, targets)` (targets carry `masks`, (1, H, W)) returns the losses; in
    eval `model(images)` returns per image {boxes (0 or 1, 4), scores, labels} from `mask_box`."""

    def __init__(self, backbone: str, channels: int, score_thresh: float, pretrained: str | None) -> None:
        super().__init__()
        self.body = timm_features(backbone, pretrained, STRIDE_INDICES)
        self.norm = InputNorm(self.body)
        self.lateral = nn.ModuleList(nn.Conv2d(c, channels, 1) for c in self.body.feature_info.channels())
        self.smooth = nn.ModuleList(
            nn.Sequential(
                nn.Conv2d(channels, channels, 3, padding=1, bias=False),
                nn.BatchNorm2d(channels),
                nn.ReLU(inplace=True),
            )
            for _ in STRIDE_INDICES[:-1]
        )
        self.logit = nn.Conv2d(channels, 1, 1)
        nn.init.constant_(self.logit.bias, PRIOR_LOGIT)
        self.score_thresh = score_thresh

    def logits(self, x: Tensor) -> Tensor:
        """(B, 1, H, W) mask logits of (B, 3, H, W) RGB in [0, 1]."""
        maps = self.body(self.norm(x))
        y = self.lateral[-1](maps[-1])
        for level in range(len(maps) - 2, -1, -1):
            up = F.interpolate(y, size=maps[level].shape[-2:], mode="bilinear", align_corners=False)
            y = self.smooth[level](self.lateral[level](maps[level]) + up)
        return F.interpolate(self.logit(y), size=x.shape[-2:], mode="bilinear", align_corners=False)

    def forward(
        self, images: list[Tensor], targets: list[dict[str, Tensor]] | None = None
    ) -> dict[str, Tensor] | list[dict[str, Tensor]]:
        logits = self.logits(torch.stack(images))
        if self.training:
            assert targets is not None, "training takes targets with masks"
            masks = torch.stack([t["masks"].to(logits.dtype) for t in targets])
            return mask_losses(logits, masks)
        out = []
        for prob in torch.sigmoid(logits[:, 0]).detach().float().cpu().numpy():
            found = mask_box(prob, self.score_thresh)
            boxes, scores = (found[0][None], [found[1]]) if found else (np.zeros((0, 4)), [])
            out.append({"boxes": torch.tensor(boxes, dtype=torch.float32),
                        "scores": torch.tensor(scores, dtype=torch.float32),
                        "labels": torch.ones(len(scores), dtype=torch.int64)})  # fmt: skip
        return out
