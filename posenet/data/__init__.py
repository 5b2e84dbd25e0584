"""Reading scgen / BOP-layout datasets into RoI samples with GDR-Net targets (see dataset.py)."""

from posenet.data.dataset import PoseDataset, open_split
from posenet.data.sampler import EpochSampler

__all__ = ["EpochSampler", "PoseDataset", "open_split"]
