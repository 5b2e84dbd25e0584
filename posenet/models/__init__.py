"""GDR-Net / GAP-GDRNet pose networks: `create_model(variant, preset, **overrides)` builds every one.

The configuration vocabularies load at once; the networks (torch, timm) on first use, so that the command
lines answer --help without torch."""

from typing import Any

from posenet.models.config import PRESETS, VARIANTS, ModelConfig, Variant

__all__ = ["PRESETS", "VARIANTS", "ModelConfig", "PoseNet", "Variant", "create_model"]


def __getattr__(name: str) -> Any:
    if name in ("PoseNet", "create_model"):
        from posenet.models import posenet

        return getattr(posenet, name)
    raise AttributeError(f"module 'posenet.models' has no attribute {name!r}")
