"""AFR feature-response heat maps (paper Fig. 7): ℓ2 norm over channels, min–max normalised per image."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

from posenet.models import PoseNet


def feature_response(features: Tensor, size: int | None = None) -> Tensor:
    """B×C×H×W feature → B×H×W map in [0, 1] (B×size×size when `size` is given, for overlays).

    A constant map (no contrast) comes out as zeros rather than NaN.
    """
    norm = features.detach().float().norm(dim=1, keepdim=True)
    if size is not None:
        norm = F.interpolate(norm, size=(size, size), mode="bilinear", align_corners=False)
    lo = norm.amin(dim=(2, 3), keepdim=True)
    span = norm.amax(dim=(2, 3), keepdim=True) - lo
    return ((norm - lo) / span.clamp_min(torch.finfo(norm.dtype).tiny)).squeeze(1)


@torch.no_grad()
def model_feature_response(model: PoseNet, roi_img: Tensor, roi_coord2d: Tensor) -> Tensor:
    """Heat map of the feature before the geometric output conv (after AFR when enabled), RoI-sized.

    Runs the model in eval mode and restores its previous mode afterwards.
    """
    was_training = model.training
    model.eval()
    try:
        features = model(roi_img, roi_coord2d)["features"]
    finally:
        model.train(was_training)
    return feature_response(features, size=roi_img.shape[-1])
