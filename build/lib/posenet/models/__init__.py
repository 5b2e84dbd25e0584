"""GDR-Net / GAP-GDRNet pose networks: `create_model(variant, preset, **overrides)` builds every one."""

from .config import PRESETS, VARIANTS, ModelConfig, Variant
from .posenet import PoseNet, create_model

__all__ = ["PRESETS", "VARIANTS", "ModelConfig", "PoseNet", "Variant", "create_model"]
