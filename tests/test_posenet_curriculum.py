"""The attitude curriculum: where a pose sits in attitude is the cone draw scgen recorded, the corridor
widens linearly in solid angle to every instance, its batches are deterministic, resumable and sharded,
and a run trains with it on a real dataset."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from posenet.cli import main
from posenet.config import config_from_dict
from posenet.data import CurriculumSampler
from posenet.data.curriculum import cone_cap_deg, line_of_sight_tilt_deg
from posenet.errors import PosenetError
from scgen.generator import Generator
from scgen.scenes import load_config
from scgen.scenes.attitude import nominal_rotation

NOMINAL = [0.8, 0.2, -0.5, 0.26]  # not the identity, so a frame mix-up shows


def cap_share(angle_deg: float) -> float:
    """The share of the sphere a cap of half-angle `angle_deg` holds."""
    return (1.0 - math.cos(math.radians(angle_deg))) / 2.0


def test_the_tilt_from_a_pose_is_the_cone_draw_scgen_recorded(spacecraft) -> None:
    pose = {"distribution": "cone", "nominal": NOMINAL, "max_angle_deg": 150.0, "roll_deg": [-180.0, 180.0]}
    generator = Generator(spacecraft, load_config(overrides={"pose": pose}), 3)
    scenes = [generator.scene(i) for i in range(300)]
    R = np.stack([s.target.R_mat for s in scenes])
    t = np.stack([s.target.t_vec for s in scenes])
    tilts = line_of_sight_tilt_deg(R, t, nominal_rotation(generator.cfg["pose"]))
    np.testing.assert_allclose(tilts, [s.cone.cone_deg for s in scenes], atol=1e-6)
    assert tilts.max() > 120.0  # the draws span the cone, so a wrong axis could not pass


def test_the_corridor_widens_linearly_in_solid_angle_from_the_start_cone_to_every_instance() -> None:
    rng = np.random.default_rng(0)
    tilts = np.degrees(np.arccos(rng.uniform(-1.0, 1.0, 20_000)))  # lines of sight uniform on the sphere
    sampler = CurriculumSampler(tilts, batch_size=8, world=1, rank=0, seed=0, start_deg=20.0, widen_steps=100)
    for step, share in ((0, cap_share(20.0)), (50, (1 + cap_share(20.0)) / 2), (100, 1.0), (500, 1.0)):
        assert sampler.eligible(step) / len(tilts) == pytest.approx(share, abs=0.01)
    assert cone_cap_deg(20.0, 0.0) == pytest.approx(20.0) and cone_cap_deg(20.0, 1.0) == pytest.approx(180.0)
    sampler.set_epoch(0)
    drawn = np.array([i for _, i in sampler]).reshape(-1, 8)  # 2,500 steps: widened after the first 100
    for step in (0, 10, 60, 99):
        assert tilts[drawn[step]].max() <= cone_cap_deg(20.0, step / 100) + 1e-9
    assert tilts[drawn[100:]].max() > 170.0 and np.median(tilts[drawn[100:]]) == pytest.approx(90.0, abs=3.0)


def test_curriculum_batches_are_deterministic_resumable_and_sharded() -> None:
    tilts = np.linspace(0.0, 180.0, 400)
    one = CurriculumSampler(tilts, 8, 1, 0, seed=3, start_deg=30.0, widen_steps=60)
    ranks = [CurriculumSampler(tilts, 4, 2, r, seed=3, start_deg=30.0, widen_steps=60) for r in (0, 1)]
    for s in (one, *ranks):
        s.set_epoch(1)
    whole = [i for _, i in one]
    halves = [[i for _, i in s] for s in ranks]
    assert whole == [i for _, i in one]  # a function of (seed, epoch) alone
    for b in range(one.steps_per_epoch):  # each rank takes its half of every global batch
        assert sorted(whole[8 * b : 8 * b + 8]) == sorted(
            halves[0][4 * b : 4 * b + 4] + halves[1][4 * b : 4 * b + 4]
        )
    one.set_epoch(1, skip_batches=7)
    assert [i for _, i in one] == whole[7 * 8 :] and len(one) == len(whole) - 7 * 8


def test_a_bad_curriculum_is_refused_in_one_line() -> None:
    for data in ({"curriculum_deg": 200.0}, {"curriculum_deg": 20.0, "curriculum_widen": 0.0}):
        with pytest.raises(PosenetError, match=r"data.curriculum_deg must lie in \[0, 180\]"):
            config_from_dict({"preset": "smoke", "data": data})


def test_a_run_trains_with_the_curriculum_on_a_real_dataset(small_dataset: Path, tmp_path: Path) -> None:
    config = tmp_path / "curriculum.yaml"
    config.write_text(
        "preset: smoke\n"
        "model: {input_res: 64, output_res: 16, head_channels: 32, pnp_channels: 32, fc_dims: [64, 32]}\n"
        "data: {workers: 1, curriculum_deg: 60.0}\n"
        "optim: {batch_size: 2, epochs: 2, warmup_iters: 1}\n"
    )
    res = CliRunner().invoke(
        main, ["train", "--data", str(small_dataset), "--out", str(tmp_path / "run"), "--config", str(config)]
    )
    assert res.exit_code == 0, res.output
    assert "curriculum: from " in res.output and (tmp_path / "run" / "last.pt").is_file()
