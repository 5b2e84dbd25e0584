"""posenet: GDR-Net / GAP-GDRNet 6D pose networks trained and evaluated on scgen (BOP-layout) datasets.

The Python API, loaded on first use (so that `import posenet` stays light): `posenet.train` (a run, as
`posenet train`), `posenet.evaluate` (a checkpoint on a split, as `posenet eval`), `posenet.Predictor`
and `posenet.Pose` (a pose from any image, as `posenet predict`), `posenet.make_camera`.

OpenMP's idle threads wait passively here (OMP_WAIT_POLICY=PASSIVE, unless the environment sets it):
otherwise torch's intra-op threads spin at every barrier, and on a shared CPU (the loader processes,
other jobs) a spinning thread holds the core that the thread it waits for needs. On 2 shared cores that
made a smoke-preset training step take 4-12 s instead of ~1 s. OpenMP reads the variable once, when torch
is imported: importing posenet first sets it.
"""

import os
from typing import Any

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

# the `posenet` command's imports (torch, timm), timed by posenet.console: a training run's first seconds
IMPORT_SECONDS: float | None = None

# the facade: attribute -> the module that defines it
API = {
    "train": "posenet.training.train",
    "evaluate": "posenet.evaluation.evaluate",
    "Predictor": "posenet.predict.predictor",
    "Pose": "posenet.predict.predictor",
    "make_camera": "posenet.data.camera",
}
__all__ = list(API)


def __getattr__(name: str) -> Any:
    if name in API:
        import importlib

        return getattr(importlib.import_module(API[name]), name)
    raise AttributeError(f"module 'posenet' has no attribute {name!r}")
