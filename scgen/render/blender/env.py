"""Loading bpy and choosing the Cycles device, with one-line ScgenErrors instead of import tracebacks."""

from __future__ import annotations

import contextlib
import importlib.util
import os
import re
import sys
from collections.abc import Iterator
from types import ModuleType
from typing import Any

from scgen.errors import ScgenError
from scgen.io.cores import seeing_cores

BPY_PYTHON = (3, 11)  # the bpy 5.0 wheels are built for CPython 3.11 only
GPU_BACKENDS = ("OPTIX", "CUDA", "HIP", "ONEAPI")  # in order of preference
DEVICES = ("auto", "cpu", "gpu")
# Importing bpy puts Blender's script folders first on sys.path; a process spawned by one that did
# inherits them, and their pure-Python `bpy` package then shadows the real module ("No module
# named '_bpy'"). They are dropped before the first import; bpy adds them back itself.
BLENDER_SCRIPTS = re.compile(r"[/\\]bpy[/\\]\d+\.\d+[/\\]scripts([/\\]|$)")


def check_bpy() -> None:
    """Raise a ScgenError when bpy cannot be imported here, without importing it (about 1 s, 300 MB)."""
    if sys.version_info[:2] != BPY_PYTHON:
        raise ScgenError(
            f"the blender backend needs bpy, which supports Python {BPY_PYTHON[0]}.{BPY_PYTHON[1]} only "
            f"(this is {sys.version_info[0]}.{sys.version_info[1]}); use a 3.11 venv or --backend mitsuba"
        )
    if "bpy" not in sys.modules and importlib.util.find_spec("bpy") is None:
        raise ScgenError(_missing("No module named 'bpy'"))


def import_bpy(threads: int | None = None) -> ModuleType:
    """The bpy module, or a ScgenError saying why it cannot be used here. `threads`: the size of Blender's
    task scheduler (TBB) where this call imports bpy (None: every core). Blender sizes it from the cores
    the process sees at import; a pool larger than Cycles' render threads keeps its idle workers spinning
    (sched_yield) through every render, on the cores the other workers render on: with 2 workers of one
    render thread on 2 cores, each spent 2.4 s of CPU a sample instead of 1.2 (half of it system time)."""
    check_bpy()
    if "bpy" not in sys.modules:
        sys.path[:] = [p for p in sys.path if not BLENDER_SCRIPTS.search(p)]
    try:
        with seeing_cores(threads):
            import bpy
    except ImportError as exc:
        raise ScgenError(_missing(str(exc))) from exc
    return bpy


def _missing(reason: str) -> str:
    return f"the blender backend needs bpy ({reason}): pip install 'scgen[render]', or use --backend mitsuba"


def check_device(device: str) -> None:
    if device not in DEVICES:
        raise ScgenError(f"unknown device '{device}' (choose from {', '.join(DEVICES)})")


def gpu_devices(bpy: ModuleType) -> Iterator[tuple[str, list[Any]]]:
    """Each GPU API Cycles finds a device of, in order of preference, with the API's device list (which
    also holds the CPU); each API is the selected one while it is yielded."""
    prefs = bpy.context.preferences.addons["cycles"].preferences
    for api in GPU_BACKENDS:
        with quiet_stdout():  # Cycles prints a warning for every GPU library it fails to open
            prefs.compute_device_type = api
            devices = prefs.get_devices_for_type(api)
        if any(d.type == api for d in devices):
            yield api, devices


def select_device(bpy: ModuleType, device: str) -> str:
    """Enable the Cycles compute device for `device` (auto|cpu|gpu); returns 'CPU' or the GPU API used."""
    check_device(device)
    prefs = bpy.context.preferences.addons["cycles"].preferences
    if device != "cpu":
        for api, devices in gpu_devices(bpy):
            for d in devices:
                d.use = d.type == api
            return api
    prefs.compute_device_type = "NONE"
    if device == "gpu":
        raise ScgenError(
            f"--device gpu: Cycles finds no GPU ({'/'.join(GPU_BACKENDS)}); use --device cpu or auto"
        )
    return "CPU"


@contextlib.contextmanager
def quiet_stdout() -> Iterator[None]:
    """Silence Blender's C-level stdout (per-render 'Saved:' lines) so progress bars stay readable."""
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)
