"""The package as pip installs it: a wheel built from the source carries the bundled model and renders it
from a folder outside the checkout."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCE_ONLY = shutil.ignore_patterns(
    ".git", ".venv", "__pycache__", "*.egg-info", "build", "demo_out", ".*cache"
)


def run(*command: str, cwd: Path, **env: str) -> subprocess.CompletedProcess:
    done = subprocess.run(
        command, cwd=cwd, env={**os.environ, **env}, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return done


def test_the_wheel_carries_the_bundled_model_and_renders_it_outside_the_checkout(tmp_path: Path) -> None:
    source, wheels, site, work = (tmp_path / d for d in ("source", "wheels", "site", "work"))
    shutil.copytree(ROOT, source, ignore=SOURCE_ONLY)
    run(sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(wheels),
        ".", cwd=source)  # fmt: skip
    (wheel,) = wheels.glob("scgen-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    model = {f"scgen/assets/spacecraft/{f}" for f in ("parts.glb", "obj_000001.ply", "models_info.json")}
    assert model <= names, sorted(n for n in names if "assets" in n)
    run(
        sys.executable,
        "-m",
        "pip",
        "install",
        "--no-deps",
        "-q",
        "--target",
        str(site),
        str(wheel),
        cwd=tmp_path,
    )
    work.mkdir()
    where = run(sys.executable, "-c", "import scgen; print(scgen.__file__)", cwd=work, PYTHONPATH=str(site))
    assert where.stdout.strip() == str(site / "scgen" / "__init__.py")  # the installed copy, not the checkout
    render = ["render", "--backend", "mitsuba", "--n", "2", "--resolution", "64x48", "--quality", "draft",
              "--workers", "1", "--quiet", "--out", "ds"]  # fmt: skip
    done = run(sys.executable, "-m", "scgen.cli", *render, cwd=work, PYTHONPATH=str(site))
    assert "2/2 on disk" in done.stdout and "scgen:" not in done.stderr
    run(sys.executable, "-m", "scgen.cli", "validate", "ds", "--workers", "1", cwd=work, PYTHONPATH=str(site))
