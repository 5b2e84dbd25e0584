"""timm backbones as stride-32 feature extractors, randomly initialised or from a local state dict."""

from __future__ import annotations

from pathlib import Path

import timm
from torch import Tensor, nn

from posenet.errors import PosenetError


def _checked_weights(name: str, path: str) -> dict[str, Tensor]:
    """Load a classifier checkpoint of `name` (timm or torchvision keys; the classifier may be absent).

    The check is strict apart from the classifier: a file for another architecture is refused rather
    than half-loaded (timm's own features-only loading is silently non-strict).
    """
    if not Path(path).is_file():
        raise PosenetError(f"backbone weights file not found: {path}")
    full = timm.create_model(name, pretrained=False)
    result = full.load_state_dict(timm.models.load_state_dict(path), strict=False)
    classifier = full.pretrained_cfg["classifier"]
    missing = [k for k in result.missing_keys if not k.startswith(classifier + ".")]
    if missing or result.unexpected_keys:
        raise PosenetError(
            f"{path} is not a {name} state dict: "
            f"missing {missing[:5]}, unexpected {result.unexpected_keys[:5]}"
        )
    return full.state_dict()


class Backbone(nn.Module):
    """The last (stride-32) feature map of a timm model: 512×8×8 for resnet34, 768×8×8 for convnext_tiny."""

    def __init__(self, name: str, weights: str | None = None) -> None:
        super().__init__()
        overlay = {"state_dict": _checked_weights(name, weights)} if weights else None
        self.body = timm.create_model(
            name,
            pretrained=overlay is not None,
            pretrained_cfg_overlay=overlay,
            features_only=True,
            out_indices=(-1,),
        )
        self.out_channels: int = self.body.feature_info.channels()[-1]

    def forward(self, x: Tensor) -> Tensor:
        return self.body(x)[-1]
