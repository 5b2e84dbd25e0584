"""timm backbones as feature extractors, randomly initialised or from a local state dict."""

from __future__ import annotations

from pathlib import Path

import timm
from timm.layers import LayerNorm2d
from torch import Tensor, nn

from posenet.errors import PosenetError


def checked_weights(name: str, path: str) -> dict[str, Tensor]:
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


def open_residual_init(name: str) -> dict[str, object]:
    """timm arguments that start every residual branch open when training from random init.

    timm zero-initialises the last BN of each ResNet block (`zero_init_last`) and scales each ConvNeXt
    block by 1e-6 (`ls_init_value`), so a fresh backbone is its stem plus the strided shortcuts: a
    ~20 px receptive field at stride 32. Measured here: after 780 CPU steps the ResNet gammas were still
    ~0.01, the branches never opened, and xyz, regions and pose did not learn (docs/posenet.md).
    """
    if name.startswith(("resnet", "regnet")):
        return {"zero_init_last": False}
    if name.startswith("convnext"):
        return {"ls_init_value": 1.0}
    return {}


def timm_features(name: str, weights: str | None, out_indices: tuple[int, ...]) -> nn.Module:
    """timm's features-only `name` returning the maps of `out_indices`: from the local classifier state
    dict `weights` (checked strictly), or from random init with the residual branches open."""
    overlay = {"state_dict": checked_weights(name, weights)} if weights else None
    body = timm.create_model(
        name,
        pretrained=overlay is not None,
        pretrained_cfg_overlay=overlay,
        features_only=True,
        out_indices=out_indices,
        **(open_residual_init(name) if overlay is None else {}),
    )
    if overlay is None and isinstance(getattr(body, "stem_1", None), nn.LayerNorm | LayerNorm2d):
        # From scratch timm zeroes the ConvNeXt stem bias: a flat patch (black space) then gives equal
        # channels, LayerNorm divides by sqrt(eps) and the bias gradient explodes. A small random bias
        # keeps the channels apart; pretrained weights are left untouched.
        nn.init.normal_(body.stem_0.bias, std=0.02)
    return body


class Backbone(nn.Module):
    """The last (stride-32) feature map of a timm model: 512×8×8 for resnet34, 768×8×8 for convnext_tiny."""

    def __init__(self, name: str, weights: str | None = None) -> None:
        super().__init__()
        self.body = timm_features(name, weights, (-1,))
        self.out_channels: int = self.body.feature_info.channels()[-1]

    def forward(self, x: Tensor) -> Tensor:
        return self.body(x)[-1]
