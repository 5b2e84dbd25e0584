"""Model configuration: one dataclass, the seven paper variants as named presets of it."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, NamedTuple

from posenet.errors import PosenetError


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

# Small timm backbones of the same family for the CPU smoke preset.
SMOKE_BACKBONES = {"resnet34": "resnet18", "convnext_tiny": "convnext_atto"}


def backbone_family(backbone: str) -> str:
    """'resnet' or 'convnext' for the timm names we use; the name itself otherwise."""
    return next((f for f in ("resnet", "convnext") if backbone.startswith(f)), backbone)


@dataclass(frozen=True)
class ModelConfig:
    """Architecture of a GDR-Net / GAP-GDRNet model; defaults are the paper's full GAP-GDRNet.

    The backbone is a timm name with a stride-32 last feature map; the geometric head upsamples it ×8,
    so `output_res` must be `input_res / 4`. `pretrained` is a local backbone state dict (timm or
    torchvision ImageNet checkpoint of the same architecture); it only affects initialisation and is
    therefore not part of `to_dict()`.
    """

    backbone: str = "convnext_tiny"
    ggca: bool = True
    mecs: bool = True
    pgsa: bool = True
    input_res: int = 256
    output_res: int = 64
    head_channels: int = 256
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
            object.__setattr__(self, name, tuple(getattr(self, name)))
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
        )
        failed = [message for ok, message in rules if not ok]
        if failed:
            raise PosenetError("invalid ModelConfig: " + "; ".join(failed))

    @classmethod
    def paper(cls, variant: str = "gap-gdrnet", **overrides: Any) -> ModelConfig:
        """The paper's configuration of `variant` (256² input, 256-ch head, 128-ch Patch-PnP)."""
        return cls(**{**_variant(variant)._asdict(), **overrides})

    @classmethod
    def smoke(cls, variant: str = "gap-gdrnet", **overrides: Any) -> ModelConfig:
        """Reduced-width CPU preset of `variant`: small backbone, 64-ch head, 128² input, 32² output.

        Every module of the variant (AFR branches, PGSA) is kept, only narrower.
        """
        v = _variant(variant)
        small = dict(
            backbone=SMOKE_BACKBONES[v.backbone],
            input_res=128,
            output_res=32,
            head_channels=64,
            pnp_channels=64,
            fc_dims=(256, 128),
        )
        return cls(**{**v._asdict(), **small, **overrides})

    @property
    def variant(self) -> str:
        """Name of the paper variant this configuration is an instance of, or 'custom'."""
        family = backbone_family(self.backbone)
        for name, v in VARIANTS.items():
            if (backbone_family(v.backbone), v.ggca, v.mecs, v.pgsa) == (
                family,
                self.ggca,
                self.mecs,
                self.pgsa,
            ):
                return name
        return "custom"

    def to_dict(self) -> dict[str, Any]:
        """JSON-able architecture description (no `pretrained`): equal dicts mean compatible weights."""
        d = dataclasses.asdict(self)
        del d["pretrained"]
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ModelConfig:
        """Inverse of `to_dict` (extra keys such as 'variant' are ignored)."""
        fields = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in fields})


def _variant(name: str) -> Variant:
    if name not in VARIANTS:
        raise PosenetError(f"unknown variant {name!r}; choose one of {', '.join(VARIANTS)}")
    return VARIANTS[name]
