"""Mitsuba on a libLLVM it cannot use: the run finishes on scalar_rgb (same labels), or on a newer libLLVM.

Real renders with the machine's own libLLVMs: LLVM 15 aborts on Dr.Jit's fminimum/fmaximum kernels,
Dr.Jit refuses 14; both are tested where the machine has them, a path that does not exist everywhere.
"""

from __future__ import annotations

import glob
import json
import os
import shutil
import subprocess
import sys
from dataclasses import asdict
from pathlib import Path

import pytest

from scgen.io.machine_cache import CACHE_ENV
from scgen.render.mitsuba.llvm import (
    LIBLLVM_ENV,
    LIBLLVM_GLOBS,
    VERDICT_ENV,
    VERDICTS_KEPT,
    Libllvm,
    libllvm_major,
    machine_key,
    newer_libllvms,
    probe_libllvm,
    remember_verdict,
    verdict_file,
)
from scgen.run.runner import RenderJob, run_render

NOTICE = "scgen: Mitsuba cannot render with"
ROOT = Path(__file__).resolve().parents[1]


def machine_libllvm(major: int) -> str | None:
    """A libLLVM of this major version on this machine, or None."""
    return next((p for g in LIBLLVM_GLOBS for p in sorted(glob.glob(g)) if libllvm_major(p) == major), None)


def scgen(*args: str, cwd: Path | None = None, **env: str) -> subprocess.CompletedProcess:
    """`scgen ARGS` in a fresh process (in `cwd`), with this environment less any libLLVM choice, plus
    `env`."""
    base = {k: v for k, v in os.environ.items() if k not in (LIBLLVM_ENV, VERDICT_ENV)}
    command = [sys.executable, "-m", "scgen.cli", *args]
    return subprocess.run(command, env={**base, **env}, capture_output=True, text=True, timeout=600, cwd=cwd)


def render_args(out: Path) -> list[str]:
    return ["render", "--backend", "mitsuba", "--n", "2", "--resolution", "160x120", "--workers", "2",
            "--quality", "draft", "--quiet", "--out", str(out)]  # fmt: skip


def labels(root: Path) -> dict[str, bytes]:
    """Every label file of a dataset (masks, xyz maps, BOP JSON), by relative path; the images, and the
    records and metadata.csv that also describe them (e.g. their saturated share), left out."""
    files = [p for p in root.rglob("*") if p.is_file() and p.parent.name not in ("rgb", "records")
             and p.suffix != ".csv"]  # fmt: skip
    return {str(p.relative_to(root)): p.read_bytes() for p in files if p.parent != root}


@pytest.fixture(scope="module")
def llvm_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The two samples rendered by this process (the LLVM variant where its libLLVM works)."""
    out = tmp_path_factory.mktemp("llvm") / "ds"
    run_render(RenderJob(out, 2, backend="mitsuba", quality="draft", resolution=(160, 120), workers=2), False)
    return out


OLD = [pytest.param(machine_libllvm(m), id=f"libLLVM-{m}",
                    marks=pytest.mark.skipif(machine_libllvm(m) is None, reason=f"no libLLVM {m} here"))
       for m in (15, 14)]  # fmt: skip


@pytest.mark.parametrize("libllvm", [*OLD, pytest.param("/nonexistent/libLLVM.so", id="missing")])
def test_unusable_libllvm_renders_on_scalar_with_one_notice_and_the_same_labels(
    libllvm: str, llvm_dataset: Path, tmp_path: Path
):
    done = scgen(*render_args(tmp_path / "ds"), **{LIBLLVM_ENV: libllvm})
    assert done.returncode == 0, done.stderr
    notices = [line for line in done.stderr.splitlines() if line.startswith(NOTICE)]
    assert len(notices) == 1, done.stderr  # decided once, in the parent; both workers inherit it
    assert "rendering with scalar_rgb" in notices[0] and "apt-get install libllvm19" in notices[0]
    assert not [line for line in done.stderr.splitlines() if line.startswith("LLVM ERROR")]  # no abort
    assert "2/2 on disk" in done.stdout
    assert labels(tmp_path / "ds") == labels(llvm_dataset)


def test_old_default_libllvm_gives_way_to_a_newer_one_on_the_machine(tmp_path: Path):
    old = machine_libllvm(15)
    if old is None or not newer_libllvms(Libllvm(old, "15", None)):
        pytest.skip("needs libLLVM 15 and a newer libLLVM on this machine")
    (tmp_path / "lib").mkdir()
    (tmp_path / "lib" / "libLLVM.so").symlink_to(old)  # Dr.Jit's first pick: libLLVM.so on the library path
    done = scgen(*render_args(tmp_path / "ds"), LD_LIBRARY_PATH=str(tmp_path / "lib"))
    assert done.returncode == 0, done.stderr
    notices = [line for line in done.stderr.splitlines() if line.startswith(NOTICE)]
    assert len(notices) == 1 and "libLLVM 15" in notices[0] and "found on this machine" in notices[0]
    assert "2/2 on disk" in done.stdout


def test_a_check_that_fails_before_mitsuba_names_its_own_cause_without_libllvm_advice(tmp_path: Path):
    """The package without its bundled model (as a wheel that did not ship it): the libLLVM check's test
    render fails before Mitsuba starts, and says so in one line naming the missing model, no LLVM advice;
    the render then stops on the same cause."""
    without_model = shutil.ignore_patterns("__pycache__", "spacecraft")  # the package data left out
    shutil.copytree(ROOT / "scgen", tmp_path / "pkg" / "scgen", ignore=without_model)
    # run outside the checkout, whose scgen `python -m` would put first on the path; a machine scgen has
    # not run on (no verdict file), so the check runs
    env = {"PYTHONPATH": str(tmp_path / "pkg"), CACHE_ENV: str(tmp_path / "cache")}
    done = scgen(*render_args(tmp_path / "ds"), cwd=tmp_path, **env)
    lines = done.stderr.splitlines()
    notices = [line for line in lines if line.startswith("scgen: ")]
    assert done.returncode == 1 and len(notices) == 1, done.stderr
    assert notices[0].startswith("scgen: libLLVM not checked: its test render failed before Mitsuba started:")
    assert "bundled model missing" in notices[0] and "libllvm19" not in done.stderr
    assert lines[-1].startswith("Error: bundled model missing")


def test_a_libllvm_that_rendered_is_trusted_from_the_verdict_file_until_the_machine_changes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    monkeypatch.delenv(LIBLLVM_ENV, raising=False)
    first = probe_libllvm(None)  # a real test render in a child process
    if first.error is not None:
        pytest.skip(f"Dr.Jit's own libLLVM does not render here: {first.error}")
    verdicts = json.loads(verdict_file().read_text())
    assert verdicts == {machine_key(None): asdict(first)}
    # the next probe answers from the file: an entry changed there comes back as it is written
    verdicts[machine_key(None)]["version"] = "as the file says"
    verdict_file().write_text(json.dumps(verdicts))
    assert probe_libllvm(None).version == "as the file says"
    assert probe_libllvm(None, fresh=True) == first  # scgen doctor renders again
    # what the verdict rests on changes: another search path for the loader, another libLLVM asked for
    key = machine_key(None)
    assert machine_key(first.path) != key
    monkeypatch.setenv("LD_LIBRARY_PATH", str(tmp_path))
    assert machine_key(None) != key


def test_a_failed_probe_leaves_no_verdict(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """A libLLVM that cannot render is probed again next time (its failure may have passed): a file that is
    not a libLLVM fails the test render, and nothing is written."""
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    fake = tmp_path / "libLLVM.so.99"
    fake.write_bytes(b"not a shared library")
    assert probe_libllvm(str(fake)).error is not None
    assert not verdict_file().exists()


def test_the_verdict_file_keeps_its_newest_entries(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    verdict = Libllvm("/usr/lib/libLLVM.so.19", "19.1.7", None)
    for k in range(VERDICTS_KEPT + 4):
        remember_verdict(f"key{k}", verdict)
    remember_verdict("key2", verdict)  # an old key written again is the newest
    keys = list(json.loads(verdict_file().read_text()))
    assert len(keys) == VERDICTS_KEPT and keys[-1] == "key2"
    assert keys[:-1] == [f"key{k}" for k in range(5, VERDICTS_KEPT + 4)]
