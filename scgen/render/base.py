"""The backend protocol: a renderer turns a SceneSpec into Buffers and knows nothing of files."""

from __future__ import annotations

import importlib.util
from collections.abc import Mapping
from typing import Protocol

from scgen.errors import ScgenError
from scgen.io.buffers import Buffers
from scgen.io.cores import usable_cores
from scgen.render.conventions import MITSUBA_THREADS
from scgen.scenes.model import TargetModel
from scgen.scenes.spec import SceneSpec

BACKENDS = ("blender", "mitsuba")


class Backend(Protocol):
    """One renderer instance per worker process, kept alive across samples."""

    name: str

    def render(self, spec: SceneSpec) -> Buffers: ...

    def close(self) -> None: ...


MITSUBA_MISSING = {  # Blender's labels are Mitsuba ray casts too
    "mitsuba": "the mitsuba backend needs Mitsuba 3: pip install 'scgen[mitsuba]'",
    "blender": "the blender backend casts its labels through Mitsuba 3: pip install 'scgen[render]'",
}


def check_backend(name: str, device: str = "auto") -> None:
    """Fail fast, before anything is written, when a backend cannot run here; builds no renderer here.

    Only `--device gpu` imports bpy (to ask Cycles for a GPU); otherwise the modules are only located.
    Mitsuba's variant and libLLVM are settled here, by a child process, before drjit is imported.
    """
    if name not in BACKENDS:
        raise ScgenError(f"unknown backend '{name}' (choose from {', '.join(BACKENDS)})")
    if importlib.util.find_spec("mitsuba") is None:
        raise ScgenError(MITSUBA_MISSING[name])
    if name == "mitsuba":
        from scgen.render.mitsuba.llvm import mitsuba_setup

        mitsuba_setup()
    else:
        from scgen.render.blender.env import check_bpy, check_device, import_bpy, select_device

        check_bpy()
        check_device(device)
        if device == "gpu":
            select_device(import_bpy(), device)


def create_backend(
    name: str, model: TargetModel, quality: str = "default", device: str = "auto", threads: int | None = None,
    models: Mapping[int, TargetModel] | None = None,
) -> Backend:  # fmt: skip
    """Instantiate a backend by name; raises ScgenError for unknown names or a missing renderer.

    `threads`: the renderer's CPU threads; None = the backend's default for one worker (renderer_threads).
    `models`: every object's model by obj_id (the target's is `model`), for SceneSpec.objects.
    """
    check_backend(name)  # the device is the backend's to choose (Blender probes the GPUs once)
    threads = renderer_threads(name, 1, threads)
    if name == "mitsuba":
        from scgen.render.mitsuba.backend import MitsubaBackend

        return MitsubaBackend(model, quality=quality, threads=threads, models=models)
    from scgen.render.blender.backend import BlenderBackend

    return BlenderBackend(model, quality=quality, device=device, threads=threads, models=models)


def renderer_threads(name: str, workers: int, threads: int | None = None) -> int:
    """CPU threads for the renderer of each of `workers` workers: `threads` when given; else Blender's share
    of the cores (Cycles' pixels do not depend on its thread count) and Mitsuba's MITSUBA_THREADS."""
    if threads:
        return threads
    return MITSUBA_THREADS if name == "mitsuba" else max(1, usable_cores() // workers)
