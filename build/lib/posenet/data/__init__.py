"""Reading scgen / BOP-layout datasets into RoI samples with GDR-Net targets (see dataset.py)."""

from .dataset import PoseDataset, open_split
from .sampler import EpochSampler

__all__ = ["EpochSampler", "PoseDataset", "open_split"]
