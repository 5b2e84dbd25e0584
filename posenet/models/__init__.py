"""GDR-Net / GAP-GDRNet pose networks: `build_model(name, ModelConfig(...))` for every paper variant."""

from .config import VARIANTS, ModelConfig, Variant
from .posenet import PoseNet, build_model

__all__ = ["VARIANTS", "ModelConfig", "PoseNet", "Variant", "build_model"]
