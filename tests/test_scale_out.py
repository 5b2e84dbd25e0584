"""Workers, shards, merge and crash-safe resume give the same dataset as one clean run (Ray, on workers
running the installed wheel: test_packaging)."""

from __future__ import annotations

import filecmp
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import psutil
import pytest
from click.testing import CliRunner

from scgen.cli import main

N = 8
COMMON = [
    "--n",
    str(N),
    "--backend",
    "mitsuba",
    "--quality",
    "draft",
    "--resolution",
    "160x120",
    "--seed",
    "3",
]


def render(out: Path, *extra: str) -> None:
    result = CliRunner().invoke(main, ["render", "--out", str(out), *COMMON, "--quiet", *extra])
    assert result.exit_code == 0, result.output


def files(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())


def assert_same_dataset(a: Path, b: Path) -> None:
    assert files(a) == files(b)
    different = [f for f in files(a) if not filecmp.cmp(a / f, b / f, shallow=False)]
    assert different == []


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("ref") / "one_worker"
    render(out, "--workers", "1")
    return out


def test_two_workers_and_merged_shards_equal_one_worker(reference: Path, tmp_path: Path):
    render(tmp_path / "two", "--workers", "2")
    assert_same_dataset(reference, tmp_path / "two")
    render(tmp_path / "s0", "--workers", "1", "--shard", "0/2")
    render(tmp_path / "s1", "--workers", "1", "--shard", "1/2")
    result = CliRunner().invoke(
        main, ["merge", str(tmp_path / "merged"), str(tmp_path / "s0"), str(tmp_path / "s1")]
    )
    assert result.exit_code == 0, result.output
    assert_same_dataset(reference, tmp_path / "merged")


def start_render(out: Path, workers: int) -> subprocess.Popen:
    """`scgen render` of the COMMON settings as a process of its own (its own session, quiet)."""
    cmd = [sys.executable, "-m", "scgen.cli", "render", "--out", str(out), *COMMON, "--workers", str(workers)]
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    return subprocess.Popen([*cmd, "--quiet"], start_new_session=True, **quiet)


def wait_for_samples(out: Path, count: int) -> None:
    deadline = time.time() + 120
    while time.time() < deadline and len(list(out.glob("*/*/records/*.json"))) < count:
        time.sleep(0.05)


def test_kill_9_then_resume_equals_clean_run(reference: Path, tmp_path: Path):
    out = tmp_path / "killed"
    proc = start_render(out, workers=2)
    wait_for_samples(out, 3)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    n_before = len(list(out.glob("*/*/records/*.json")))
    assert 0 < n_before < N, "the kill must land mid-run"
    render(out, "--workers", "2")
    assert_same_dataset(reference, out)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_workers_end_with_a_killed_render_process(tmp_path: Path, sig: signal.Signals):
    """Only the main process is signalled (as a job scheduler or `kill PID` does): its renderers must not
    outlive it."""
    out = tmp_path / "orphans"
    proc = start_render(out, workers=2)
    wait_for_samples(out, 1)
    workers = [c for c in psutil.Process(proc.pid).children() if "spawn_main" in " ".join(c.cmdline())]
    assert len(workers) == 2
    proc.send_signal(sig)
    proc.wait()
    _, alive = psutil.wait_procs(workers, timeout=15)
    for p in alive:
        p.kill()
    assert alive == [], "worker processes outlived the killed render"


def test_a_worker_killed_mid_run_is_replaced_and_its_sample_retried(reference: Path, tmp_path: Path):
    out = tmp_path / "chaos"
    killed: list[int] = []

    def kill_one_worker() -> None:
        deadline = time.time() + 60
        while time.time() < deadline and not killed:
            if list(out.glob("*/*/records/*.json")):
                for child in psutil.Process().children(recursive=True):
                    try:
                        if "spawn_main" in " ".join(child.cmdline()):
                            child.kill()
                            killed.append(child.pid)
                            return
                    except psutil.Error:  # exited meanwhile
                        continue
            time.sleep(0.02)

    killer = threading.Thread(target=kill_one_worker)
    killer.start()
    render(out, "--workers", "2")
    killer.join()
    assert killed, "no worker was killed: the test did not exercise the retry path"
    assert_same_dataset(reference, out)


def test_resume_refuses_other_settings(reference: Path, tmp_path: Path):
    out = tmp_path / "copy"
    render(out, "--workers", "1", "--shard", "0/4")
    other_seed = [*COMMON[:-1], "4"]
    result = CliRunner().invoke(main, ["render", "--out", str(out), *other_seed, "--quiet"])
    assert result.exit_code != 0 and "refusing to resume" in result.output and "seed" in result.output


EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
# (config text or example file, --n, --resolution, samples): 3 sequences of 3 frames (the frames of a
# sequence spread over the shards), and 4 images of several labelled objects each (their masks, xyz maps
# and models of every obj_id merged and resumed as the target's)
KINDS = {
    "sequence": ("[sequence]\nframes = 3\ndt_s = 5.0\nattitude_probs = {tumble = 1.0}\n", 3, "64x48", 9),
    "objects": (EXAMPLES / "servicer_client.toml", 4, "160x120", 4),
}


@pytest.mark.parametrize("kind", KINDS)
def test_workers_shards_and_resume_equal_one_run(tmp_path: Path, kind: str):
    """A sequence's frames, or a scene's several labelled objects, are byte-identical with one worker, two,
    merged shards, or resumed from a shard."""
    source, n, resolution, total = KINDS[kind]
    config = source if isinstance(source, Path) else tmp_path / "config.toml"
    if not isinstance(source, Path):
        config.write_text(source)
    seq = ["--config", str(config), "--n", str(n), "--resolution", resolution]
    render(tmp_path / "one", "--workers", "1", *seq)
    render(tmp_path / "two", "--workers", "2", *seq)
    assert_same_dataset(tmp_path / "one", tmp_path / "two")
    render(tmp_path / "s0", "--workers", "1", "--shard", "0/2", *seq)
    render(tmp_path / "s1", "--workers", "1", "--shard", "1/2", *seq)
    result = CliRunner().invoke(
        main, ["merge", str(tmp_path / "merged"), str(tmp_path / "s0"), str(tmp_path / "s1")]
    )
    assert result.exit_code == 0, result.output
    assert f"{total}/{total} samples" in result.output
    assert_same_dataset(tmp_path / "one", tmp_path / "merged")
    render(tmp_path / "s0", "--workers", "1", *seq)  # resumes shard 0's samples into the whole job
    assert_same_dataset(tmp_path / "one", tmp_path / "s0")
