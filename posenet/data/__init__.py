"""Reading scgen / BOP-layout datasets into RoI samples with GDR-Net targets (see dataset.py)."""

from posenet.data.dataset import PoseDataset, open_split
from posenet.data.sampler import CurriculumSampler, EpochSampler

__all__ = ["CurriculumSampler", "EpochSampler", "PoseDataset", "open_split"]
