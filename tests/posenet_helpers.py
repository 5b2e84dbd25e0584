"""Shared by the posenet tests: one small rendered dataset per session, a briefly trained checkpoint."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner
from shared_dirs import shared_dir

from posenet.cli import main as posenet_main
from scgen.run.runner import RenderJob, run_render

# the smoke preset shrunk to a 64 px crop: a checkpoint in seconds for the eval and box-file tests
TINY_POSE = """\
preset: smoke
model: {input_res: 64, output_res: 16, head_channels: 32, pnp_channels: 32, fc_dims: [64, 32]}
data: {workers: 0}
optim: {batch_size: 4, epochs: 1}
"""
N_IMAGES = 24
RESOLUTION = (320, 240)
# The images the learning test's thresholds were measured on: an ideal camera, the procedural sky and
# the CAD finishes (scgen's defaults before its camera, real sky and drawn finishes). Under the new
# defaults 16 training images no longer generalise to the 8 held-out ones within the test's budget
# (held-out mask IoU 0.34 vs the majority mask's 0.33, translation ratio 0.77; docs/benchmarks.md): that is
# a finding about the data's difficulty, measured separately, not a regression of the learner.
AS_BEFORE_REALISM = {
    "background": {"earth_map": "procedural", "stars": "procedural"},
    "finish": {"mode": "nominal"},
}


def cli_ok(*args: object, code: int = 0) -> str:
    """`posenet ARGS` through its command line in this process; its output, the exit status asserted."""
    res = CliRunner().invoke(posenet_main, [str(a) for a in args])
    assert res.exit_code == code, res.output
    return res.output


def posenet_dataset(tmp_path_factory: pytest.TempPathFactory, seed: int = 0) -> Path:
    """N_IMAGES samples of `seed` rendered with Mitsuba at 320x240 as before scgen's realism
    (AS_BEFORE_REALISM), read-only for tests; seed 1's are scenes the seed-0 set never holds. Rendered
    once per session, shared by every module and worker (shared_dirs)."""

    def build(out: Path) -> None:
        job = RenderJob(
            out=out, n=N_IMAGES, seed=seed, backend="mitsuba", quality="draft", resolution=RESOLUTION,
            camera="ideal", overrides=AS_BEFORE_REALISM,
        )  # fmt: skip
        run_render(job, progress=False)

    return shared_dir(tmp_path_factory, "posenet_ds" if seed == 0 else f"posenet_ds_seed{seed}", build)


def occluded_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """6 samples of seed 0, all in 'train', each target 80-95 % hidden by an occluder (the heavy group)."""

    def build(out: Path) -> None:
        heavy = {"group_probs": {"none": 0.0, "slight": 0.0, "moderate": 0.0, "heavy": 1.0}}
        job = RenderJob(
            out=out,
            n=6,
            seed=0,
            backend="mitsuba",
            quality="draft",
            resolution=RESOLUTION,
            overrides={"occluders": {**heavy, "target_r_occ": {"heavy": [0.8, 0.95]}}},
            ratios=(1.0, 0.0, 0.0),
        )
        run_render(job, progress=False)

    return shared_dir(tmp_path_factory, "posenet_occluded_ds", build)


def tiny_pose_checkpoint(
    dataset: Path, tmp_path_factory: pytest.TempPathFactory, variant: str = "gdrnet"
) -> Path:
    """`posenet train` with TINY_POSE (of `variant`) for 2 steps on `dataset`; the path of its last.pt.
    Trained once per session for each dataset and variant, shared read-only (shared_dirs)."""

    def build(root: Path) -> None:
        root.mkdir(parents=True)
        (root / "tiny.yaml").write_text(TINY_POSE)
        args = ["train", "--data", dataset, "--out", root / "run", "--config", root / "tiny.yaml"]
        args += ["--max-steps", 2, "--variant", variant]
        res = CliRunner().invoke(posenet_main, [str(a) for a in args])
        assert res.exit_code == 0, res.output

    return shared_dir(tmp_path_factory, f"tiny_{variant}_on_{dataset.name}", build) / "run" / "last.pt"


def calibrate_untrained(data: Path, ckpt: Path) -> None:
    """`posenet calibrate` of an untrained checkpoint on `data`'s test split. The untrained network is never
    confident, so --min-confidence 0 takes every pose for a measurement."""
    args = (
        "calibrate",
        "--data",
        data,
        "--ckpt",
        ckpt,
        "--split",
        "test",
        "--workers",
        0,
        "--min-confidence",
        0,
    )
    res = CliRunner().invoke(posenet_main, [str(a) for a in args])
    assert res.exit_code == 0, res.output
