"""The backend protocol: a renderer turns a SceneSpec into Buffers and knows nothing of files."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from scgen.errors import ScgenError
from scgen.model import TargetModel
from scgen.scenes.spec import SceneSpec

BACKGROUND_ID = 0
TARGET_ID = 1  # props get ids 2, 3, ... in SceneSpec.props order
BACKENDS = ("blender", "mitsuba")


@dataclass
class Buffers:
    """Per-pixel renderer output, all H x W, OpenCV pixel-centre convention.

    depth / target_depth: z along the optical axis in metres, 0 where nothing is hit.
    instance: BACKGROUND_ID, TARGET_ID, or 2 + index into SceneSpec.props.
    normal: camera-frame unit normal facing the camera (zeros on background).
    sun_blocked: the ray from the visible surface towards the sun hits a non-target object.
    """

    rgb: np.ndarray  # uint8 H x W x 3 (sRGB)
    depth: np.ndarray  # float32
    instance: np.ndarray  # int32
    target_depth: np.ndarray  # float32, the target rendered alone (for the full mask)
    normal: np.ndarray  # float32 H x W x 3
    sun_blocked: np.ndarray  # bool


class Backend(Protocol):
    """One renderer instance per worker process, kept alive across samples."""

    name: str

    def render(self, spec: SceneSpec) -> Buffers: ...

    def close(self) -> None: ...


def create_backend(
    name: str, model: TargetModel, quality: str = "default", device: str = "auto", threads: int | None = None
) -> Backend:
    """Instantiate a backend by name; raises ScgenError for unknown names or a missing renderer.

    `threads` caps the renderer's CPU threads (several workers share the cores); None = all cores.
    """
    if name == "mitsuba":
        from scgen.render.mitsuba_backend import MitsubaBackend

        return MitsubaBackend(model, quality=quality, threads=threads)
    if name == "blender":
        from scgen.render.blender import BlenderBackend

        return BlenderBackend(model, quality=quality, device=device, threads=threads)
    raise ScgenError(f"unknown backend '{name}' (choose from {', '.join(BACKENDS)})")
