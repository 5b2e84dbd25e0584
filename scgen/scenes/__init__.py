"""Scene sampling: SceneSpec data, per-factor random streams (here), the configuration (config/) and
rendezvous motion (motion/). No renderer imports here."""

from scgen.scenes.config.scene import load_config
from scgen.scenes.sampler import sample_scene
from scgen.scenes.silhouette import TargetShape
from scgen.scenes.spec import SceneSpec

__all__ = ["SceneSpec", "TargetShape", "load_config", "sample_scene"]
