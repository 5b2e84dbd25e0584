"""The backend protocol: a renderer turns a SceneSpec into Buffers and knows nothing of files."""

from __future__ import annotations

import importlib.util
from typing import Protocol

from scgen.errors import ScgenError
from scgen.render.buffers import Buffers
from scgen.scenes.model import TargetModel
from scgen.scenes.spec import SceneSpec

BACKENDS = ("blender", "mitsuba")


class Backend(Protocol):
    """One renderer instance per worker process, kept alive across samples."""

    name: str

    def render(self, spec: SceneSpec) -> Buffers: ...

    def close(self) -> None: ...


def check_backend(name: str, device: str = "auto") -> None:
    """Fail fast, before anything is written, when a backend cannot run here; builds no renderer here.

    Only `--device gpu` imports bpy (to ask Cycles for a GPU); otherwise the modules are only located.
    Mitsuba's variant and libLLVM are settled here, by a child process, before drjit is imported.
    """
    if name == "mitsuba":
        if importlib.util.find_spec("mitsuba") is None:
            raise ScgenError("the mitsuba backend needs the mitsuba package: pip install mitsuba")
        from scgen.render.mitsuba_llvm import mitsuba_setup

        mitsuba_setup()
    elif name == "blender":
        from scgen.render.blender_env import check_bpy, check_device, import_bpy, select_device

        check_bpy()
        check_device(device)
        if device == "gpu":
            select_device(import_bpy(), device)
    else:
        raise ScgenError(f"unknown backend '{name}' (choose from {', '.join(BACKENDS)})")


def create_backend(
    name: str, model: TargetModel, quality: str = "default", device: str = "auto", threads: int | None = None
) -> Backend:
    """Instantiate a backend by name; raises ScgenError for unknown names or a missing renderer.

    `threads` caps the renderer's CPU threads (several workers share the cores); None = all cores.
    """
    check_backend(name)  # the device is the backend's to choose (Blender probes the GPUs once)
    if name == "mitsuba":
        from scgen.render.mitsuba_backend import MitsubaBackend

        return MitsubaBackend(model, quality=quality, threads=threads)
    from scgen.render.blender import BlenderBackend

    return BlenderBackend(model, quality=quality, device=device, threads=threads)
