"""Training runs on a real rendered dataset: resume, DDP (gloo, 2 processes), config, and refusals."""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
import yaml
from budget_checks import assert_the_decay_ends_at_the_budget
from click.testing import CliRunner

from posenet.cli import main
from posenet.config import OptimConfig, load_config
from posenet.data.layout import scan_split
from posenet.training.budget import TimeBudget
from posenet.training.train import cpu_threads, loader_workers, lr_factor, throughput
from scgen.io import usable_cores

TIMES = ("step_s", "wait_s")  # what a log row measures of the wall clock; the rest is arithmetic
TINY = """\
preset: smoke
model: {input_res: 64, output_res: 16, head_channels: 32, pnp_channels: 32, fc_dims: [64, 32]}
data: {workers: 1, pad_scale: 1.5}
optim: {batch_size: 4, epochs: 10, warmup_iters: 2, ckpt_every: 100}
"""


@pytest.fixture
def tiny_config(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.yaml"
    path.write_text(TINY)
    return path


def posenet(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(main, [str(a) for a in args])
    return res.exit_code, res.output


def losses(run: Path) -> dict[int, float]:
    return {r["step"]: r["loss"] for r in map(json.loads, (run / "train_log.jsonl").read_text().splitlines())}


def test_schedule_warms_up_stays_flat_then_anneals_to_zero() -> None:
    o = OptimConfig(warmup_iters=10, warmup_factor=0.001, anneal_point=0.72)
    f = [lr_factor(i, 100, o) for i in range(101)]
    # 0.001 (1 - 0) + 0, and 0.001 x 0.5 (exact) + 0.5 rounded once, to 0.5005's float: equal, not approx
    assert f[0] == 0.001 and f[5] == 0.5005
    assert f[10] == f[50] == f[72] == 1.0
    # float64: a few u64 from the formulas' values, inside approx's rel 1e-6; at the end cos(pi) is -1 to
    # a u64, so the factor 0.5 (1 + cos) is 0 within 1e-16
    assert f[86] == pytest.approx(0.5) and f[100] == pytest.approx(0.0, abs=1e-12)
    assert all(a >= b for a, b in zip(f[72:], f[73:], strict=False))


def test_resume_continues_with_the_identical_next_step_loss(
    dataset_dir: Path, tiny_config: Path, tmp_path: Path
) -> None:
    straight, stopped = tmp_path / "straight", tmp_path / "stopped"
    code, out = posenet(
        "train", "--data", dataset_dir, "--out", straight, "--config", tiny_config, "--max-steps", 5
    )
    assert code == 0, out
    # data.workers 1; on a CPU whose cores the training threads all take, the training process loads
    started, why = re.search(
        r"(\d+) loader processes \(samples path(; data.workers 1 would share [^)]*)?\)", out
    ).groups()
    assert (why is not None) == (int(started) < 1)
    code, out = posenet(
        "train", "--data", dataset_dir, "--out", stopped, "--config", tiny_config, "--max-steps", 3
    )
    assert code == 0, out
    assert torch.load(stopped / "last.pt", weights_only=True)["step"] == 3
    code, out = posenet("train", "--data", dataset_dir, "--out", stopped, "--resume", "--max-steps", 5)
    assert code == 0, out
    a, b = losses(straight), losses(stopped)
    assert sorted(b) == [1, 2, 3, 4, 5]
    assert b[4] == a[4] and b[5] == a[5]  # bit-identical: same weights, optimizer state and batches
    saved = yaml.safe_load((stopped / "config.yaml").read_text())
    assert load_config(str(stopped / "config.yaml")).to_dict() == saved
    assert (stopped / "tb").is_dir()


def test_loader_processes_on_a_cpu_get_only_the_cores_the_training_threads_leave() -> None:
    """A loader process on a core the step's threads use stalls the step (loader_workers); beside a GPU
    every requested loader process starts."""
    cpu = torch.device("cpu")
    assert loader_workers(2, cpu, threads=2, cores=2) == 0
    assert loader_workers(2, cpu, threads=1, cores=2) == 1
    assert loader_workers(2, cpu, threads=4, cores=16) == 2
    assert loader_workers(2, cpu, threads=8, cores=4) == 0
    assert loader_workers(4, torch.device("cuda"), threads=16, cores=16) == 4


@pytest.mark.parametrize(
    ("threads", "env", "expected"),
    [(3, "5", 3), (0, "5", 5)] + [(0, env, usable_cores()) for env in (None, "0", "two", "")],
)
def test_training_threads_are_the_config_s_else_omp_num_threads_else_one_per_core(
    threads: int, env: str | None, expected: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """optim.threads wins; at 0 a positive OMP_NUM_THREADS (a job script sharing a node) sets the count,
    and anything else in it is ignored for one thread per core the process may run on."""
    if env is None:
        monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OMP_NUM_THREADS", env)
    assert cpu_threads(threads) == expected


def test_same_config_and_seed_give_the_same_losses_whatever_ran_before(
    dataset_dir: Path, tiny_config: Path, tmp_path: Path
) -> None:
    """Training pins its thread count: a caller that changed it (e.g. `posenet bench --threads 1` in the
    same process) does not change the float summation order, hence not the losses."""
    before = torch.get_num_threads()
    runs = []
    for threads in (2, 1):
        torch.set_num_threads(threads)
        run = tmp_path / f"threads{threads}"
        code, out = posenet(
            "train", "--data", dataset_dir, "--out", run, "--config", tiny_config, "--max-steps", 4
        )
        assert code == 0, out
        runs.append(losses(run))
    torch.set_num_threads(before)
    assert runs[0] == runs[1] and len(runs[0]) == 4


def test_losses_read_back_every_log_every_steps_are_the_losses_of_every_step(
    dataset_dir: Path, tmp_path: Path
) -> None:
    """The loop reads the losses back from the device every optim.log_every steps, several steps' rows in
    one transfer (and the rest at the stop): the log holds the same rows as when every step is read."""
    rows = {}
    for every in (1, 3):
        config = tmp_path / f"every{every}.yaml"
        config.write_text(TINY.replace("ckpt_every: 100", f"ckpt_every: 100, log_every: {every}"))
        run = tmp_path / f"every{every}"
        code, out = posenet(
            "train", "--data", dataset_dir, "--out", run, "--config", config, "--max-steps", 5
        )
        assert code == 0, out
        lines = (run / "train_log.jsonl").read_text().splitlines()
        rows[every] = [{k: v for k, v in json.loads(ln).items() if k not in TIMES} for ln in lines]
    assert [r["step"] for r in rows[3]] == [1, 2, 3, 4, 5]
    assert rows[3] == rows[1]


def test_a_step_cap_beyond_the_schedule_is_reported(
    dataset_dir: Path, tiny_config: Path, tmp_path: Path
) -> None:
    run = tmp_path / "run"
    code, out = posenet(
        "train",
        "--data",
        dataset_dir,
        "--out",
        run,
        "--config",
        tiny_config,
        "--epochs",
        "1",
        "--max-steps",
        "1000",
    )
    steps = len(losses(run))
    assert code == 0 and f"exceeds the schedule's {steps} steps" in out and steps < 1000


def test_ddp_with_gloo_on_two_processes(dataset_dir: Path, tiny_config: Path, tmp_path: Path) -> None:
    """`torchrun --standalone --nproc-per-node 2 -m posenet.cli train` (gloo): the global batch of 4 is
    split 2 + 2 (4 images a step, 16 training images: 4 steps an epoch), both processes end with identical
    weights, and the checkpoint resumes in a single process."""
    out = tmp_path / "ddp"
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node", "2"]
    cmd += ["-m", "posenet.cli", "train", "--data", str(dataset_dir), "--out", str(out)]
    cmd += ["--config", str(tiny_config), "--max-steps", "5"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    print(proc.stdout)
    assert "DDP: 2 processes, largest weight difference: 0.0e+00" in proc.stdout
    state = torch.load(out / "last.pt", weights_only=True)
    assert state["world_size"] == 2 and state["step"] == 5 and state["rank_weight_spread"] == 0.0
    rows = [json.loads(line) for line in (out / "train_log.jsonl").read_text().splitlines()]
    assert [(r["step"], r["epoch"], r["images"]) for r in rows] == [
        (1, 0, 4),
        (2, 0, 4),
        (3, 0, 4),
        (4, 0, 4),
        (5, 1, 4),
    ]
    code, output = posenet("train", "--data", dataset_dir, "--out", out, "--resume", "--max-steps", 7)
    assert code == 0, output
    state = torch.load(out / "last.pt", weights_only=True)
    assert state["world_size"] == 1 and state["step"] == 7
    assert sorted(losses(out)) == [1, 2, 3, 4, 5, 6, 7]


def test_refusals_are_one_line_and_write_nothing(
    dataset_dir: Path, tiny_config: Path, tmp_path: Path
) -> None:
    code, out = posenet(
        "train", "--data", tmp_path / "nothing", "--out", tmp_path / "r0", "--config", tiny_config
    )
    assert (
        code == 1
        and out.startswith("Error:")
        and "not a dataset" in out
        and len(out.strip().splitlines()) == 1
    )
    assert not (tmp_path / "r0").exists()
    code, out = posenet(
        "train", "--data", dataset_dir, "--out", tmp_path / "r1", "--config", tmp_path / "nope.yaml"
    )
    assert code == 1 and "neither a preset" in out
    bad = tmp_path / "bad.yaml"
    bad.write_text("optim: {learning_rate: 1.0}\n")
    code, out = posenet("train", "--data", dataset_dir, "--out", tmp_path / "r1", "--config", bad)
    assert code == 1 and "unknown config key 'optim.learning_rate'" in out
    run = tmp_path / "run"
    code, out = posenet(
        "train", "--data", dataset_dir, "--out", run, "--config", tiny_config, "--max-steps", 1
    )
    assert code == 0, out
    code, out = posenet(
        "train", "--data", dataset_dir, "--out", run, "--config", tiny_config, "--max-steps", 1
    )
    assert code == 1 and "already holds a run" in out
    code, out = posenet("train", "--data", dataset_dir, "--out", run, "--resume", "--variant", "gap-gdrnet")
    assert code == 1 and "from another configuration" in out and len(out.strip().splitlines()) == 1
    assert losses(run) == {1: losses(run)[1]}
    code, out = posenet("eval", "--data", dataset_dir, "--ckpt", tiny_config)
    assert code == 1 and "not a readable checkpoint" in out
    code, out = posenet("train", "--data", dataset_dir, "--out", tmp_path / "r2", "--amp", "fp8")
    assert code == 1 and out.strip() == "Error: optim.amp must be one of auto, off, bf16, fp16, got 'fp8'"
    code, out = posenet("--version")
    assert code == 0 and out.startswith("posenet, version ")


def test_a_time_budget_refits_the_schedule_to_the_time_left_and_fixes_it_when_the_cosine_begins() -> None:
    budget = TimeBudget(seconds=100.0, anneal_point=0.72, start=0.0)
    clock, step, froze_at, times = 10.0, 0, None, []  # 10 s of start-up, 1 s a step, 0.5 s from step 40
    while froze_at is None:
        step += 1
        clock += 1.0 if step <= 40 else 0.5
        times.append(clock)
        if budget.update(step, clock):
            froze_at = step
    # the steps left at the recent rate (the later half of the steps done) fill the time left
    since = froze_at // 2
    rate = (clock - times[since - 1]) / (froze_at - since)
    assert budget.total == froze_at + int((100.0 - clock) / rate)
    assert froze_at >= 0.72 * budget.total > froze_at - 1
    # the speed-up is in the estimate: at 0.5 s a step the fitted end falls within 2 % of the budget
    assert abs(clock + 0.5 * (budget.total - froze_at) - 100.0) < 2.0
    assert budget.expired(100.0) and not budget.expired(99.9)
    fitted = budget.total  # at the fitted rate the decay keeps it: the next step is a step ahead of the clock
    assert not budget.update(froze_at + 1, clock + 0.5) and budget.frozen and budget.total == fitted


def test_a_time_budget_that_slows_during_the_decay_brings_its_end_forward() -> None:
    """0.1 s a step until the cosine begins, then 0.3 s: the steps left no longer fit the time left, so
    the total comes forward (never back) and the rate the run ends on is the cosine's end, as the train
    loop sets it (the scheduler's rate for step s + 1 computed before the budget sees step s)."""
    o = OptimConfig(warmup_iters=0, anneal_point=0.72)
    budget = TimeBudget(seconds=100.0, anneal_point=o.anneal_point, start=0.0)
    clock, step, lr, used = 0.0, 0, lr_factor(0, budget.total, o), []
    while True:
        step += 1
        clock += 0.3 if budget.frozen else 0.1
        used.append(lr)
        lr = lr_factor(step, budget.total, o)  # scheduler.step(), then the budget's update
        if budget.update(step, clock):
            fitted, decay_start, start_clock = budget.total, step, clock
        if budget.expired(clock) or step >= budget.total:
            break
    assert budget.total < fitted and step <= budget.total  # a third of the fitted steps fit the time left
    assert all(b <= a for a, b in zip(used[decay_start:], used[decay_start + 1 :], strict=False))
    # the rate of the last step lags the clock by at most two steps (0.6 s) of the decay's time, 100 - the
    # clock at the cosine's start: progress >= 1 - 0.6 / (100 - start_clock), the rate (1 + cos) / 2 of it
    lag = 0.6 / (100.0 - start_clock)
    assert used[-1] <= (1 + math.cos(math.pi * (1 - lag))) / 2
    without = (1 + math.cos(math.pi * (step - decay_start) / (fitted - decay_start))) / 2
    assert without > 0.5  # where the total stayed fixed, the run would have stopped with half its rate left


def test_minutes_train_a_fitted_schedule_that_ends_at_the_budget(dataset_dir: Path, tmp_path: Path) -> None:
    run = tmp_path / "budget"
    # one thread: two threads' OpenMP barriers on a loaded 2-core machine stretched the tiny steps to 17 s,
    # where one thread slows only by its share of the cores
    config = tmp_path / "one_thread.yaml"
    config.write_text(TINY.replace("ckpt_every: 100}", "ckpt_every: 100, threads: 1}"))
    tic = time.perf_counter()
    code, out = posenet("train", "--data", dataset_dir, "--out", run, "--config", config, "--minutes", 0.5)
    wall = time.perf_counter() - tic
    assert code == 0, out
    fitted = re.search(r"schedule fitted to (\d+) steps, cosine from step (\d+)", out)
    assert fitted and "this run stops at the budget" in out, out
    total, cosine = int(fitted[1]), int(fitted[2])
    assert cosine >= OptimConfig().anneal_point * total
    rows = [json.loads(ln) for ln in (run / "train_log.jsonl").read_text().splitlines()]
    schedule = torch.load(run / "last.pt", weights_only=False)["schedule_steps"]
    assert_the_decay_ends_at_the_budget(rows, total, schedule, OptimConfig().anneal_point)
    # it stops at the budget or at its schedule's end, never before both; past the budget by at most the
    # step under way and the checkpoint written at the end
    assert wall >= 30.0 or rows[-1]["step"] == schedule
    assert wall < 30.0 + rows[-1]["step_s"] + 8.0
    code, out = posenet("train", "--data", dataset_dir, "--out", run, "--resume", "--minutes", 1)
    assert (
        code == 1
        and "--minutes fits a new run's whole schedule" in out
        and len(out.strip().splitlines()) == 1
    )


def corrupt_copy(dataset: Path, root: Path, split: str, kind: str) -> tuple[Path, Path]:
    """A copy of `dataset` whose first `split` instance's `kind` file (rgb, mask_visib, xyz) is cut to its
    first 64 bytes; the copy and that file."""
    data = root / "ds"
    shutil.copytree(dataset, data)
    inst = next(i for i in scan_split(data, split, 1) if i.px_count_visib > 0)
    path = getattr(inst, kind)
    path.write_bytes(path.read_bytes()[:64])
    return data, path


@pytest.mark.parametrize("kind, what", [("rgb", "image"), ("mask_visib", "mask"), ("xyz", "xyz map")])
def test_a_sample_that_cannot_be_read_stops_training_in_one_line_and_leaves_no_run_folder(
    dataset_dir: Path, tmp_path: Path, kind: str, what: str
) -> None:
    data, bad = corrupt_copy(dataset_dir, tmp_path, "train", kind)
    config = tmp_path / "two_loaders.yaml"
    config.write_text(TINY.replace("workers: 1", "workers: 2"))  # met in whichever loader process reads it
    run = tmp_path / "run"
    code, out = posenet("train", "--data", data, "--out", run, "--config", config, "--max-steps", 4)
    errors = [line for line in out.splitlines() if line.startswith("Error:")]
    assert code == 1 and len(errors) == 1 and "Traceback" not in out, out
    if kind == "rgb":  # an image is refused before any work, by its missing end (check_whole)
        assert errors[0].startswith("Error: 1 of the ") and f"e.g. {bad}: truncated" in errors[0], errors[0]
    else:  # met when a loader process reads it
        assert errors[0].startswith(f"Error: cannot read {what} {bad}"), errors[0]
    assert not run.exists()


def test_an_unreadable_test_image_stops_evaluation_in_one_line(dataset_dir: Path, tmp_path: Path) -> None:
    data, bad = corrupt_copy(dataset_dir, tmp_path, "test", "rgb")
    (tmp_path / "t.yaml").write_text(TINY)
    run = tmp_path / "run"
    code, out = posenet(
        "train", "--data", data, "--out", run, "--config", tmp_path / "t.yaml", "--max-steps", 1
    )
    assert code == 0, out
    code, out = posenet("eval", "--data", data, "--ckpt", run / "last.pt", "--json", tmp_path / "e.json")
    errors = [line for line in out.splitlines() if line.startswith("Error:")]
    assert code == 1 and len(errors) == 1 and "Traceback" not in out, out
    assert errors[0].startswith("Error: 1 of the ") and f"e.g. {bad}: truncated" in errors[0], errors[0]
    assert not (tmp_path / "e.json").exists()


def test_the_logged_rate_and_its_bound() -> None:
    """Samples a second are the images over the rows' wall time; the loader bounds a run whose host waited
    for batches more than half of it."""
    rows = [{"images": 8, "step_s": 0.5, "wait_s": 0.3}, {"images": 8, "step_s": 0.3, "wait_s": 0.2}]
    assert throughput(rows) == (16 / 0.8, "loader")
    assert throughput([{**r, "wait_s": 0.1} for r in rows]) == (16 / 0.8, "step")
