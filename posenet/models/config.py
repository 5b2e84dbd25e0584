"""Model configuration: one dataclass, filled from a paper variant, a size preset and overrides."""

from __future__ import annotations

import dataclasses
import types
import typing
from dataclasses import dataclass
from typing import Any, NamedTuple

from posenet.errors import PosenetError

# this module holds no torch or timm import: the command lines' help reads its vocabularies
NORMS = ("gn", "bn")  # the geometric head's norms (posenet.models.layers.norm2d)
IMAGENET = "imagenet"  # `pretrained`: timm's ImageNet weights, downloaded (posenet.models.backbone)
PACKAGE = "package"  # `pretrained`: the ImageNet weights a registry package ships, no download


class Variant(NamedTuple):
    """What distinguishes one ablation row of the paper (Table 3) from another."""

    backbone: str
    ggca: bool
    mecs: bool
    pgsa: bool


VARIANTS: dict[str, Variant] = {
    "gdrnet": Variant("resnet34", ggca=False, mecs=False, pgsa=False),
    "convnext": Variant("convnext_tiny", ggca=False, mecs=False, pgsa=False),
    "ggca": Variant("convnext_tiny", ggca=True, mecs=False, pgsa=False),
    "mecs": Variant("convnext_tiny", ggca=False, mecs=True, pgsa=False),
    "pgsa": Variant("convnext_tiny", ggca=False, mecs=False, pgsa=True),
    "afr": Variant("convnext_tiny", ggca=True, mecs=True, pgsa=False),
    "gap-gdrnet": Variant("convnext_tiny", ggca=True, mecs=True, pgsa=True),
}

PRESETS = ("paper", "smoke")
# The CPU smoke preset: every variant on one small backbone whose ImageNet weights a package ships (so the
# GDR-Net and GAP-GDRNet rows compare on one backbone), every module of the variant kept narrower.
SMOKE_FIELDS: dict[str, Any] = dict(
    backbone="tf_efficientnet_lite0",
    input_res=128,
    output_res=32,
    head_channels=64,
    pnp_channels=64,
    fc_dims=(256, 128),
)


def variant_modules(name: str) -> Variant:
    """The paper row `name` (its modules and paper backbone); an unknown name is an error."""
    if name not in VARIANTS:
        raise PosenetError(f"unknown variant {name!r}; choose one of {', '.join(VARIANTS)}")
    return VARIANTS[name]


@dataclass(frozen=True)
class ModelConfig:
    """Architecture of a GDR-Net / GAP-GDRNet model; defaults are the paper's full GAP-GDRNet.

    Make one with `ModelConfig.create(variant, preset, **overrides)`. The variant fixes the modules
    (ggca, mecs, pgsa) and its paper backbone; `backbone` may name any timm model with a stride-32 last
    feature map. The geometric head upsamples it ×8, so `output_res` must be `input_res / 4`. `pretrained`
    (None, 'imagenet', 'package' or a local file: posenet.models.backbone) only affects initialisation
    and is therefore not part of `to_dict()`.
    """

    variant: str = "gap-gdrnet"
    backbone: str = "convnext_tiny"
    ggca: bool = True
    mecs: bool = True
    pgsa: bool = True
    input_res: int = 256
    output_res: int = 64
    head_channels: int = 256
    # the geometric head's norm: 'gn' GroupNorm (GDRNPP's; the presets'), 'bn' BatchNorm (GDR-Net's)
    head_norm: str = "gn"
    pnp_channels: int = 128
    num_regions: int = 64
    fc_dims: tuple[int, ...] = (1024, 256)
    afr_groups: int = 8
    afr_reduction: int = 4
    mecs_kernels: tuple[int, ...] = (7, 11, 21)
    pgsa_heads: int = 4
    pretrained: str | None = None

    def __post_init__(self) -> None:
        for name in ("fc_dims", "mecs_kernels"):  # YAML / JSON give lists
            if isinstance(getattr(self, name), list):
                object.__setattr__(self, name, tuple(getattr(self, name)))
        hints = typing.get_type_hints(type(self))
        wrong = [
            f"{f.name} must be {_type_name(hints[f.name])}, got {getattr(self, f.name)!r}"
            for f in dataclasses.fields(self)
            if not _has_type(getattr(self, f.name), hints[f.name])
        ]
        if wrong:  # the rules below assume the types
            raise PosenetError("invalid ModelConfig: " + "; ".join(wrong))
        rules = (
            (self.input_res == 4 * self.output_res, "output_res must be input_res / 4 (stride 32, x8 head)"),
            (self.output_res % 8 == 0, "output_res must be a multiple of 8 (three stride-2 PnP blocks)"),
            (
                self.head_channels % (self.afr_groups * self.afr_reduction) == 0,
                "head_channels must be a multiple of afr_groups * afr_reduction",
            ),
            (self.pnp_channels % self.pgsa_heads == 0, "pnp_channels must be a multiple of pgsa_heads"),
            (all(k % 2 == 1 for k in self.mecs_kernels), "mecs_kernels must be odd"),
            (len(self.fc_dims) > 0, "fc_dims must not be empty"),
            (self.head_norm in NORMS, f"head_norm must be one of {', '.join(NORMS)}"),
        )
        failed = [message for ok, message in rules if not ok]
        if failed:
            raise PosenetError("invalid ModelConfig: " + "; ".join(failed))
        modules = variant_modules(self.variant)
        if (self.ggca, self.mecs, self.pgsa) != (modules.ggca, modules.mecs, modules.pgsa):
            raise PosenetError(
                f"ggca={self.ggca}, mecs={self.mecs}, pgsa={self.pgsa} is not variant {self.variant!r} "
                "(the variant sets the modules; choose the variant that has them)"
            )
        import timm  # ~2 s to import: only when a configuration is checked

        if not timm.is_model(self.backbone):
            raise PosenetError(f"unknown backbone {self.backbone!r}: not a timm model name")

    @classmethod
    def create(cls, variant: str, preset: str = "paper", **overrides: Any) -> ModelConfig:
        """The `preset` configuration of paper variant `variant`, with any fields overridden.

        The overrides must keep the variant's modules (ggca, mecs, pgsa), so a config file cannot build
        another ablation row under this one's name; the backbone is free. A checkpoint's `config_dict()`
        (every field) rebuilds its own configuration.
        """
        unknown = sorted(set(overrides) - {f.name for f in dataclasses.fields(cls)})
        if unknown:
            raise PosenetError(f"unknown model field(s): {', '.join(unknown)}")
        return cls(**{**_preset_fields(variant, preset), **overrides})

    def to_dict(self) -> dict[str, Any]:
        """JSON-able architecture description (no `pretrained`): equal dicts mean compatible weights."""
        d = dataclasses.asdict(self)
        del d["pretrained"]
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


def _preset_fields(variant: str, preset: str) -> dict[str, Any]:
    """The fields `preset` sets for paper variant `variant` (the rest keep the paper's defaults)."""
    modules = variant_modules(variant)
    if preset not in PRESETS:
        raise PosenetError(f"unknown preset {preset!r}; choose one of {', '.join(PRESETS)}")
    fields = {"variant": variant, **modules._asdict()}
    return {**fields, **SMOKE_FIELDS} if preset == "smoke" else fields


def _has_type(value: Any, hint: Any) -> bool:
    """isinstance for the field annotations used here (int, bool, str, tuple[int, ...], str | None);
    exact, so a bool is no int (YAML `true` for a width is an error)."""
    args = typing.get_args(hint)
    if typing.get_origin(hint) is tuple:
        return isinstance(value, tuple) and all(_has_type(v, args[0]) for v in value)
    if typing.get_origin(hint) is types.UnionType:
        return any(_has_type(value, a) for a in args)
    return type(value) is hint


def _type_name(hint: Any) -> str:
    """'int' for int, 'tuple[int, ...]' for the generic aliases: what an error message shows."""
    return hint.__name__ if isinstance(hint, type) else str(hint)
