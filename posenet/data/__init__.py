"""Reading scgen / BOP-layout datasets into RoI samples with GDR-Net targets (see dataset.py).

The dataset and sampler load on first use: the command lines read this package's light modules (layout,
boxes) without torch."""

from typing import Any

__all__ = ["EpochSampler", "PoseDataset", "open_split"]
HOMES = {"PoseDataset": "posenet.data.dataset", "open_split": "posenet.data.dataset",
         "EpochSampler": "posenet.data.sampler"}  # fmt: skip


def __getattr__(name: str) -> Any:
    if name in HOMES:
        import importlib

        return getattr(importlib.import_module(HOMES[name]), name)
    raise AttributeError(f"module 'posenet.data' has no attribute {name!r}")
