"""Poses from the images a user brings (`posenet predict`): any camera, a detector or given boxes, the
training crop, JSON lines, BOP / SPEED+ files and overlays. The Python API is `Predictor` and `Pose`,
loaded on first use: the command lines read this package's vocabularies (options) without torch."""

from typing import Any

__all__ = ["Camera", "Pose", "Predictor", "make_camera"]
HOMES = {"Camera": "posenet.data.camera", "make_camera": "posenet.data.camera",
         "Pose": "posenet.predict.predictor", "Predictor": "posenet.predict.predictor"}  # fmt: skip


def __getattr__(name: str) -> Any:
    if name in HOMES:
        import importlib

        return getattr(importlib.import_module(HOMES[name]), name)
    raise AttributeError(f"module 'posenet.predict' has no attribute {name!r}")
