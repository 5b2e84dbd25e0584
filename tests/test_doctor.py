"""`scgen doctor` on this machine: one verdict per line, and a non-zero exit when Cycles cannot render."""

from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

from click.testing import CliRunner

from scgen.cli import main
from tests.test_mitsuba_llvm import scgen

CHECKS = ("python", "packages", "cycles", "mitsuba", "torch", "weights", "sky", "disk")


def findings(output: str) -> dict[str, str]:
    """The report's lines by what they check."""
    lines = [line.split(maxsplit=2) for line in output.splitlines()]
    return {line[1]: f"{line[0]} {line[2]}" for line in lines if line[:1] in (["ok"], ["warn"], ["FAIL"])}


def test_doctor_reports_each_check_with_a_verdict(tmp_path: Path):
    result = CliRunner().invoke(main, ["doctor", "--out", str(tmp_path / "new" / "ds")])
    assert result.exit_code == 0, result.output
    report = findings(result.output)
    assert tuple(report) == CHECKS
    assert report["cycles"].startswith("ok renders on the CPU")
    assert report["mitsuba"].split()[:2] in (["ok", "llvm_ad_rgb"], ["warn", "scalar_rgb,"])
    assert f"free in {tmp_path}" in report["disk"]


def test_doctor_names_an_unusable_libllvm_and_its_fix():
    done = scgen("doctor", DRJIT_LIBLLVM_PATH="/nonexistent/libLLVM.so")
    assert done.returncode == 0, done.stderr  # Mitsuba on scalar_rgb does not stop the default backend
    mitsuba = findings(done.stdout)["mitsuba"]
    assert mitsuba.startswith("warn scalar_rgb, slower: /nonexistent/libLLVM.so cannot render: no such file")
    assert "| fix: apt-get install libllvm19" in mitsuba


def test_doctor_fails_when_cycles_cannot_render(tmp_path: Path):
    """bpy shadowed by Blender's own pure-Python `bpy` package (a scripts folder on the path): no _bpy."""
    wheel = Path(importlib.util.find_spec("bpy").origin).parent
    shutil.copytree(next(wheel.glob("*/scripts/modules/bpy")), tmp_path / "bpy")
    done = scgen("doctor", PYTHONPATH=str(tmp_path))
    assert done.returncode == 1
    cycles = findings(done.stdout)["cycles"]
    assert cycles.startswith("FAIL cannot render: the blender backend needs bpy (No module named '_bpy')")
    assert done.stderr.strip().splitlines()[-1].startswith("Error: the default backend (blender) cannot")
