"""The package as pip installs it: an sdist and the wheel built from it, installed into fresh venvs outside
the checkout, run from another directory through the console scripts pip writes.

The venvs take their third-party packages from the running interpreter's site-packages through a folder
of links (no download in a test) and leave out what a part's extra does not install: a training node
sees no bpy, Mitsuba or drjit, a rendering node no torch stack. scgen itself comes only from the wheel.
"""

from __future__ import annotations

import email
import importlib.metadata
import os
import shutil
import subprocess
import sys
import sysconfig
import tarfile
import zipfile
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from posenet_helpers import posenet_dataset
from test_scale_out import assert_same_dataset

from scgen.render.base import MITSUBA_MISSING
from scgen.scenes.bundled_models import BUNDLED_MODELS

ROOT = Path(__file__).resolve().parents[1]
SOURCE_ONLY = shutil.ignore_patterns(
    ".git", ".venv", "__pycache__", "*.egg-info", "build", "dist", "demo_out", ".*cache"
)
MODEL = {  # every bundled model's files
    f"scgen/assets/{name}/{f}"
    for name in BUNDLED_MODELS
    for f in ("parts.glb", "obj_000001.ply", "models_info.json")
}
RENDERERS = ("bpy", "mitsuba", "drjit")
SMALL_RENDER = ("--backend", "mitsuba", "--resolution", "64x48", "--quality", "draft", "--quiet")


def run(*command: str | Path, cwd: Path, ok: bool = True) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    done = subprocess.run(
        [str(c) for c in command], cwd=cwd, env=env, capture_output=True, text=True, timeout=900
    )
    assert (done.returncode == 0) == ok, done.stdout[-2000:] + done.stderr[-3000:]
    return done


@pytest.fixture(scope="module")
def dist(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The sdist of a copy of the source, and the wheel pip builds from that sdist (as a user's pip does)."""
    root = tmp_path_factory.mktemp("dist")
    source = root / "source"
    shutil.copytree(ROOT, source, ignore=SOURCE_ONLY)
    build = "from setuptools import build_meta as b; print(b.build_sdist('dist'))"
    name = run(sys.executable, "-c", build, cwd=source).stdout.split()[-1]
    sdist = source / "dist" / name
    run(sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", root, sdist,
        cwd=root)  # fmt: skip
    (wheel,) = root.glob("scgen-*.whl")
    return {"sdist": sdist, "wheel": wheel}


def fresh_venv(root: Path, wheel: Path, extras: str) -> tuple[Path, Path]:
    """A venv at root/venv holding the wheel and, through a folder of links, exactly the installed
    distributions that `pip install 'WHEEL[extras]'` would pull in (the wheel's requirements and theirs,
    extras and markers evaluated): a dependency the wheel forgets to declare is missing there, as on a
    user's machine. Its bin folder, and root/work, an empty folder outside the checkout to run it from."""
    where = root / "venv"
    run(sys.executable, "-m", "venv", "--without-pip", where, cwd=root)
    deps = where / "deps"
    deps.mkdir()
    site = Path(sysconfig.get_paths()["purelib"])
    for name in installed_closure(requirements(wheel, extras)):
        files = importlib.metadata.distribution(name).files or []
        for top in {f.parts[0] for f in files} - {"..", "__pycache__"}:
            if not (deps / top).exists():
                (deps / top).symlink_to(site / top)
    (venv_site,) = where.glob("lib/python3*/site-packages")
    (venv_site / "deps.pth").write_text(f"{deps}\n")
    pip = (sys.executable, "-m", "pip", "--python", where / "bin" / "python")
    run(*pip, "install", "--no-deps", "-q", wheel, cwd=root)
    (root / "work").mkdir()
    return where / "bin", root / "work"


def installed_closure(requirements: list[Requirement]) -> set[str]:
    """The names of the installed distributions these requirements pull in, transitively."""
    found: set[str] = set()
    todo = list(requirements)
    while todo:
        req = todo.pop()
        name = canonicalize_name(req.name)
        if name in found:
            continue
        try:
            dist = importlib.metadata.distribution(name)
        except importlib.metadata.PackageNotFoundError:
            pytest.fail(f"{name} (required) is not installed here: run make install")
        found.add(name)
        extras = {"", *req.extras}
        for text in dist.requires or []:
            sub = Requirement(text)
            if sub.marker is None or any(sub.marker.evaluate({"extra": e}) for e in extras):
                todo.append(sub)
    return found


def requirements(wheel: Path, extras: str) -> list[Requirement]:
    """What installing the wheel with `extras` ("a,b") asks for: the base requirements and the extras',
    with the extras they name (scgen[...]) expanded."""
    with zipfile.ZipFile(wheel) as z:
        meta = email.message_from_bytes(z.read(next(n for n in z.namelist() if n.endswith("/METADATA"))))
    reqs = [Requirement(r) for r in meta.get_all("Requires-Dist")]

    def wanted(r: Requirement, chosen: set[str]) -> bool:
        return r.marker is None or any(r.marker.evaluate({"extra": e}) for e in chosen)

    chosen: set[str] = set()
    todo = extras.split(",")
    while todo:
        chosen.add(todo.pop())
        todo += [e for r in reqs if r.name == "scgen" and wanted(r, chosen) for e in r.extras - chosen]
    return [r for r in reqs if r.name != "scgen" and wanted(r, chosen)]


def test_the_sdist_and_the_wheel_built_from_it_carry_the_bundled_model(dist: dict[str, Path]) -> None:
    with tarfile.open(dist["sdist"]) as t:
        sdist = {n.split("/", 1)[1] for n in t.getnames() if "/" in n}
    assert sdist >= MODEL | {"pyproject.toml", "README.md"}
    wheel = set(zipfile.ZipFile(dist["wheel"]).namelist())
    assert wheel >= MODEL, sorted(n for n in wheel if "assets" in n)


def test_each_extra_installs_only_its_job(dist: dict[str, Path]) -> None:
    """A training node gets no renderer and no numpy ceiling; a Mitsuba node no torch; `all` both."""
    names = {extra: {r.name.lower() for r in requirements(dist["wheel"], extra)}
             for extra in ("train", "mitsuba", "render", "all")}  # fmt: skip
    assert not names["train"] & {*RENDERERS, "bpy"} and {"torch", "timm", "openexr"} <= names["train"]
    numpy = [r for r in requirements(dist["wheel"], "train") if r.name == "numpy"]
    assert numpy and not any(s.operator in ("<", "<=", "==") for r in numpy for s in r.specifier)
    assert "mitsuba" in names["mitsuba"] and not names["mitsuba"] & {"torch", "timm", "bpy"}
    assert {"bpy", "mitsuba"} <= names["render"] and not names["render"] & {"torch", "timm"}
    assert names["train"] | names["render"] == names["all"]


def test_a_full_install_renders_validates_and_trains_from_another_directory(
    dist: dict[str, Path], tmp_path: Path
) -> None:
    bin_, work = fresh_venv(tmp_path, dist["wheel"], "all")
    code = "import scgen, posenet; print(scgen.__file__, posenet.__file__)"
    where = run(bin_ / "python", "-c", code, cwd=work)
    assert all(p.startswith(str(tmp_path / "venv" / "lib")) for p in where.stdout.split()), where.stdout
    doctor = run(bin_ / "scgen", "doctor", "--out", work, cwd=work)
    assert "FAIL" not in doctor.stdout
    render = ("--n", "10", "--split", "1,0,0", "--workers", "1", "--out", "ds")  # one batch of smoke's 8
    done = run(bin_ / "scgen", "render", *SMALL_RENDER, *render, cwd=work)
    assert "10/10 on disk" in done.stdout and "scgen:" not in done.stderr
    run(bin_ / "scgen", "validate", "ds", "--workers", "1", cwd=work)
    run(bin_ / "posenet", "train", "--data", "ds", "--out", "run", "--config", "smoke", "--max-steps", "2",
        cwd=work)  # fmt: skip
    assert (work / "run" / "last.pt").is_file()


def test_a_training_install_trains_and_evaluates_without_a_renderer(
    dist: dict[str, Path], tmp_path: Path, tmp_path_factory: pytest.TempPathFactory
) -> None:
    data = posenet_dataset(tmp_path_factory)
    bin_, work = fresh_venv(tmp_path, dist["wheel"], "train")
    for module in RENDERERS:
        run(bin_ / "python", "-c", f"import {module}", cwd=work, ok=False)
    doctor = run(bin_ / "scgen", "doctor", cwd=work).stdout  # no renderer is no failure on this node
    assert "FAIL" not in doctor and "warn  cycles    bpy not installed" in doctor, doctor
    assert "pip install 'scgen[mitsuba,render]'" in doctor and "ok    torch" in doctor, doctor
    run(bin_ / "posenet", "train", "--data", data, "--out", "run", "--config", "smoke", "--max-steps", "2",
        cwd=work)  # fmt: skip
    report = run(bin_ / "posenet", "eval", "--data", data, "--ckpt", "run/last.pt", cwd=work)
    assert "re_deg_median" in report.stdout or "rotation" in report.stdout, report.stdout
    refused = run(bin_ / "scgen", "render", *SMALL_RENDER, "--n", "1", "--out", "ds", cwd=work, ok=False)
    assert refused.stderr.strip() == f"Error: {MITSUBA_MISSING['mitsuba']}" and not (work / "ds").exists()


def test_a_rendering_install_renders_without_torch_and_says_what_posenet_needs(
    dist: dict[str, Path], tmp_path: Path
) -> None:
    bin_, work = fresh_venv(tmp_path, dist["wheel"], "render")
    run(bin_ / "python", "-c", "import torch", cwd=work, ok=False)
    done = run(bin_ / "scgen", "render", *SMALL_RENDER, "--n", "2", "--workers", "1", "--out", "ds", cwd=work)
    assert "2/2 on disk" in done.stdout
    run(bin_ / "scgen", "validate", "ds", "--workers", "1", cwd=work)
    refused = run(bin_ / "posenet", "--help", cwd=work, ok=False)
    assert refused.stderr.count("\n") == 1 and "pip install 'scgen[train]'" in refused.stderr


def test_ray_workers_running_the_installed_wheel_equal_a_local_run(
    dist: dict[str, Path], tmp_path: Path
) -> None:
    """A shared install: the Ray driver and its workers run the venv's wheel (no checkout on any path)."""
    pytest.importorskip("ray")
    bin_, work = fresh_venv(tmp_path, dist["wheel"], "render,ray")
    common = (*SMALL_RENDER, "--n", "4", "--seed", "3")
    run(bin_ / "scgen", "render", *common, "--executor", "ray", "--workers", "2", "--out", "ray", cwd=work)
    run(sys.executable, "-m", "scgen.cli", "render", *common, "--workers", "1", "--out", tmp_path / "local",
        cwd=ROOT)  # fmt: skip
    assert_same_dataset(tmp_path / "local", work / "ray")
