"""optim.compile: the training step's forward and losses through torch.compile, checked against eager mode
on a CPU (inductor's generated C++; on CUDA the same function is recorded as CUDA graphs)."""

from __future__ import annotations

import json
import math
from pathlib import Path

from click.testing import CliRunner
from posenet_helpers import TINY_POSE

from posenet.cli import main

OPTIM = "optim: {batch_size: 4, epochs: 1}"  # TINY_POSE's line


def tiny_config(compiled: bool) -> str:
    """TINY_POSE on one thread (the same summation order in both runs), warmed up in 2 steps (so that
    steps 2-3 train at a real learning rate), compiled or not."""
    assert OPTIM in TINY_POSE
    return TINY_POSE.replace(
        OPTIM,
        f"optim: {{batch_size: 4, epochs: 1, warmup_iters: 2, threads: 1, compile: {str(compiled).lower()}}}",
    )


# Step 1's losses come from the same weights and batch, so eager and compiled differ by rounding alone.
# float32 rounds each operation to 2^-24 relative; inductor fuses and reorders reductions (the longest:
# 3x3 over 1,152 channels, ~1e4 terms), whose worst-case error is ~1e4 x 2^-24 = 6e-4 relative to the
# magnitudes summed. A term's error scales with the values it is computed from, not with itself (cent is
# a difference of nearly equal numbers: it was seen 9e-4 of itself apart, 7e-6 of the total), so each
# term is held to 1e-3 of the total loss, whose terms weigh ~1 each. Further apart is not rounding.
# Observed here (2026-11-29): every term within 7e-6 of the total.
STEP1_TOL = 1e-3


def train_log(data: Path, out: Path, config: Path, steps: int) -> tuple[str, list[dict]]:
    res = CliRunner().invoke(
        main,
        ["train", "--data", str(data), "--out", str(out), "--config", str(config), "--max-steps", str(steps)],
    )
    assert res.exit_code == 0, res.output
    return res.output, [json.loads(ln) for ln in (out / "train_log.jsonl").read_text().splitlines()]


def test_compiled_step_trains_with_eager_mode_s_first_losses(dataset_dir: Path, tmp_path: Path) -> None:
    """`posenet train` with optim.compile says so, trains, and its first step's losses (same weights,
    same batch) are eager mode's to float32 rounding; later steps stay finite."""
    logs = {}
    for compiled in (False, True):
        config = tmp_path / f"{compiled}.yaml"
        config.write_text(tiny_config(compiled))
        output, logs[compiled] = train_log(dataset_dir, tmp_path / f"run-{compiled}", config, 3)
        assert ("step compiled (inductor)" in output) == compiled
    eager, compiled = logs[False], logs[True]
    assert [r["step"] for r in compiled] == [1, 2, 3]
    for key in ("loss", "coord", "mask", "region", "pm", "cent", "z"):
        assert abs(compiled[0][key] - eager[0][key]) <= STEP1_TOL * eager[0]["loss"], key
    assert all(math.isfinite(r["loss"]) for r in compiled)
