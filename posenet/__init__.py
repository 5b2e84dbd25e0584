"""posenet: GDR-Net / GAP-GDRNet 6D pose networks trained and evaluated on scgen (BOP-layout) datasets.

The Python API, loaded on first use (so that `import posenet` stays light): `posenet.train` (a run, as
`posenet train`), `posenet.evaluate` (a checkpoint on a split, as `posenet eval`), `posenet.Predictor`
and `posenet.Pose` (a pose from any image, as `posenet predict`), `posenet.ObjectsPredictor` and
`posenet.ObjectPose` (every object's pose, one network per object, as `posenet predict` with several
`--ckpt`), `posenet.Tracker` (a video or sequence
on the navigation filter, as `posenet predict --track`), `posenet.make_camera`.

OpenMP's idle threads spin briefly, then sleep (GOMP_SPINCOUNT=1000, about 10 us, unless the environment
sets GOMP_SPINCOUNT or OMP_WAIT_POLICY). libgomp's default spins 300,000 times at every barrier, and on a
shared CPU (the loader processes, other jobs) a spinning thread holds the core that the thread it waits
for needs: on 2 shared cores a smoke-preset training step took 4-12 s instead of ~1 s. Never spinning
(OMP_WAIT_POLICY=PASSIVE) costs a thread's wake-up at every operator instead: 1.2x slower on 2 idle
cores (docs/posenet.md). OpenMP reads the variables once, when torch is imported: importing posenet
first sets them.
"""

import os
from typing import Any

# the variables that decide how OpenMP waits (benchmarks/throughput.py clears them for another tree's posenet)
OPENMP_WAITING = ("GOMP_SPINCOUNT", "OMP_WAIT_POLICY")
if "OMP_WAIT_POLICY" not in os.environ:  # a user's wait policy stands, as does a user's spin count
    os.environ.setdefault("GOMP_SPINCOUNT", "1000")  # libgomp's own count for an oversubscribed machine

# `posenet train`'s imports (torch, timm), timed by the command (posenet.cli): a training run's first seconds
IMPORT_SECONDS: float | None = None

# the facade: attribute -> the module that defines it
API = {
    "train": "posenet.training.train",
    "evaluate": "posenet.evaluation.evaluate",
    "Predictor": "posenet.predict.predictor",
    "Pose": "posenet.predict.predictor",
    "ObjectsPredictor": "posenet.predict.objects",
    "ObjectPose": "posenet.predict.objects",
    "Tracker": "posenet.predict.track",
    "make_camera": "posenet.data.camera",
}
__all__ = list(API)


def __getattr__(name: str) -> Any:
    if name in API:
        import importlib

        return getattr(importlib.import_module(API[name]), name)
    raise AttributeError(f"module 'posenet' has no attribute {name!r}")
