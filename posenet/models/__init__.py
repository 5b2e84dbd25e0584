"""GDR-Net / GAP-GDRNet pose networks: `create_model(variant, preset, **overrides)` builds every one."""

from posenet.models.config import PRESETS, VARIANTS, ModelConfig, Variant
from posenet.models.posenet import PoseNet, create_model

__all__ = ["PRESETS", "VARIANTS", "ModelConfig", "PoseNet", "Variant", "create_model"]
