"""The child process of scgen.render.probe: `python -m scgen.render.probe_child mitsuba|blender` reports
what it found (the libLLVM it loaded, Cycles' GPUs) before it renders the probe sample, then its render time;
exit status 0 means the sample rendered."""

from __future__ import annotations

import json
import sys
import time
from typing import TYPE_CHECKING, Any

from scgen.render.probe import REPORT, RESOLUTION, SAMPLE

if TYPE_CHECKING:
    from scgen.scenes.model import TargetModel


def _report(**facts: Any) -> None:
    print(REPORT + json.dumps(facts), flush=True)


def _loaded_libllvm() -> str | None:
    """The libLLVM file this process has mapped (Linux), or None."""
    with open("/proc/self/maps") as maps:
        return next((line.split()[-1] for line in maps if "/libLLVM" in line), None)


def _mitsuba(model: TargetModel) -> Any:
    import drjit as dr  # loads libLLVM
    import mitsuba as mi

    from scgen.render.mitsuba.llvm import LLVM_VARIANT

    version = dr.detail.llvm_version()
    _report(libllvm=_loaded_libllvm(), version=".".join(map(str, version)) if version[0] > 0 else None)
    mi.set_variant(LLVM_VARIANT)  # the variant under test; the backend keeps a variant already set
    from scgen.render.mitsuba.backend import MitsubaBackend

    return MitsubaBackend(model, quality="draft")


def _blender(model: TargetModel) -> Any:
    from scgen.render.blender.backend import BlenderBackend
    from scgen.render.blender.env import gpu_devices, import_bpy

    gpus = {api: [d.name for d in devices if d.type == api] for api, devices in gpu_devices(import_bpy())}
    _report(gpus=gpus)
    return BlenderBackend(model, quality="draft", device="cpu")  # a first GPU render may compile for minutes


def main(backend: str) -> None:
    from scgen.scenes import TargetShape, load_config, sample_scene
    from scgen.scenes.model import load_target

    model = load_target()
    cfg = load_config(resolution=RESOLUTION)
    spec = sample_scene(*SAMPLE, cfg, TargetShape.from_mesh(model.mesh, model.diameter))
    _report(scene=True)  # what fails before this is not the renderer's (a missing model, a bad config)
    renderer = {"mitsuba": _mitsuba, "blender": _blender}[backend](model)
    start = time.perf_counter()
    renderer.render(spec)
    _report(render_s=round(time.perf_counter() - start, 2))


if __name__ == "__main__":
    from scgen.errors import ScgenError

    try:
        main(sys.argv[1])
    except ScgenError as exc:  # a renderer that cannot start here says why in one line, as the CLI does
        sys.exit(str(exc))
