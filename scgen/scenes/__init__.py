"""Scene sampling: SceneSpec data, per-factor random streams (here), the configuration (config/) and
rendezvous motion (motion/). No renderer imports here.

The names below load on first use, so that a module of motion/ (the dynamics posenet's navigation
filter shares: HCW, Euler's equations, mass properties) is imported without the sampler and its config.
"""

from importlib import import_module
from typing import Any

_HOMES = {
    "load_config": "scgen.scenes.config.scene",
    "sample_scene": "scgen.scenes.sampler",
    "TargetShape": "scgen.scenes.silhouette",
    "SceneSpec": "scgen.scenes.spec",
}
__all__ = ["SceneSpec", "TargetShape", "load_config", "sample_scene"]


def __getattr__(name: str) -> Any:
    if name in _HOMES:
        return getattr(import_module(_HOMES[name]), name)
    raise AttributeError(f"module 'scgen.scenes' has no attribute {name!r}")
