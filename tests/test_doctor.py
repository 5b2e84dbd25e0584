"""`scgen doctor` on this machine: one verdict per line, and a non-zero exit when Cycles cannot render;
the default `posenet train`'s backbone weights (posenet's check, registered with the doctor as an entry
point): cached, downloadable, or neither, and the fix."""

from __future__ import annotations

import importlib.util
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

from click.testing import CliRunner

from posenet.doctor import PROBE_S
from scgen.cli import main
from tests.test_mitsuba_llvm import scgen

CHECKS = ("python", "packages", "cycles", "mitsuba", "torch", "weights", "sky", "train", "disk")
# the registered train check alone, as the doctor reads it, in a fresh process (the Hugging Face hub reads
# its environment on import), timed
TRAIN_CHECK = """import time
from scgen.doctor import registered
import posenet.config
start = time.monotonic()
print(next(f for f in registered() if f.what == "train"))
print(f"took {time.monotonic() - start:.2f} s")
"""


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


def train_check(tmp_path: Path, **env: str) -> tuple[str, float]:
    """The doctor's train line with empty weight caches under `tmp_path` (plus `env`), and its seconds."""
    caches = {"HF_HOME": str(tmp_path / "hf"), "TORCH_HOME": str(tmp_path / "torch")}
    base = {k: v for k, v in os.environ.items() if k not in ("HF_HUB_OFFLINE", "HF_ENDPOINT")}
    done = subprocess.run([sys.executable, "-c", TRAIN_CHECK], env={**base, **caches, **env},
                          capture_output=True, text=True, timeout=300, check=True)  # fmt: skip
    line, took = done.stdout.strip().splitlines()[-2:]
    return line, float(took.split()[1])


def test_doctor_says_when_the_default_training_cannot_get_its_weights_and_names_the_fix(tmp_path: Path):
    """Not cached and the hub unreachable (a name that never resolves, then HF_HUB_OFFLINE): a warning
    naming the CPU preset and its packaged weights, in a few seconds, where timm retries for ~50 s."""
    for env in ({"HF_ENDPOINT": "https://hub.invalid"}, {"HF_HUB_OFFLINE": "1"}):
        line, took = train_check(tmp_path, **env)
        assert line.startswith(
            "warn  train     posenet train's default (paper preset, gdrnet: resnet34) cannot"
        )
        assert "timm's ImageNet weights are not cached" in line, line
        assert "| fix: posenet train --config smoke (its EfficientNet-Lite0 ImageNet weights ship" in line
        assert took < PROBE_S + 2, took  # the probe gives up after PROBE_S
    assert not any((tmp_path / "hf").rglob("*.safetensors")) and not (tmp_path / "torch").exists()


def test_doctor_finds_cached_weights_and_a_reachable_hub(tmp_path: Path):
    """timm's weights in the Hugging Face cache: ok, with the file. Not cached but the hub answers (a local
    listening socket as the endpoint): ok, the first run downloads them."""
    with socket.create_server(("127.0.0.1", 0)) as server:
        line, _ = train_check(tmp_path, HF_ENDPOINT=f"http://127.0.0.1:{server.getsockname()[1]}")
    assert (
        line.startswith("ok    train")
        and "not cached; 127.0.0.1 is reachable: the first run downloads" in line
    )
    repo = tmp_path / "hf" / "hub" / "models--timm--resnet34.a1_in1k"
    (repo / "refs").mkdir(parents=True)
    (repo / "refs" / "main").write_text("0" * 40)
    weights = repo / "snapshots" / ("0" * 40) / "model.safetensors"
    weights.parent.mkdir(parents=True)
    weights.write_bytes(b"weights")
    line, _ = train_check(tmp_path, HF_HUB_OFFLINE="1")
    assert line.startswith("ok    train     posenet train's default (paper preset, gdrnet: resnet34)")
    assert line.endswith(f": timm's ImageNet weights at {weights}")
