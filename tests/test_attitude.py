"""The target's attitude distribution: a cone (rendezvous corridor) drawn as documented, logged in
metadata.csv, checked against posenet's own allocentric conversion; uniform unchanged."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from conftest import render_dataset

from posenet.geometry import ego_to_allo
from scgen.cli import main
from scgen.errors import ScgenError
from scgen.generator import Generator
from scgen.scenes import load_config
from scgen.scenes.geometry import matrix_to_quat, quat_to_matrix

NOMINAL = [0.8, 0.2, -0.5, 0.26]  # any attitude: not the identity, so a frame mix-up shows
CONE = {
    "pose": {"distribution": "cone", "nominal": NOMINAL, "max_angle_deg": 25.0, "roll_deg": [-10.0, 30.0]}
}


def corridor_place(R: np.ndarray, t: np.ndarray) -> tuple[float, float]:
    """(tilt of the line of sight from the nominal one, roll about it), in degrees, recomputed from an
    egocentric pose with posenet's allocentric conversion: M = R_allo R_nominal^T = Rz(roll) Rtilt, so
    the tilt is the angle M turns the optical axis by, and the roll is the twist of M about it."""
    R_allo = ego_to_allo(torch.from_numpy(R)[None], torch.from_numpy(t)[None])[0].numpy()
    q0 = np.asarray(NOMINAL) / np.linalg.norm(NOMINAL)
    M = R_allo @ quat_to_matrix(q0).T
    tilt = np.degrees(np.arccos(np.clip(M[2, 2], -1.0, 1.0)))
    w, _, _, z = matrix_to_quat(M)
    return float(tilt), float(np.degrees(2 * np.arctan2(z, w)))


def test_cone_draws_the_line_of_sight_uniformly_over_the_cap_and_the_roll_over_its_range(spacecraft):
    generator = Generator(spacecraft, load_config(overrides=CONE), 5)
    places = np.array(
        [corridor_place(s.target.R_mat, s.target.t_vec) for s in map(generator.scene, range(800))]
    )
    tilt, roll = places.T
    # the pose's float64 turns the drawn tilt by sqrt(2 x 32 u64) rad = 5e-6 deg at most, where arccos is
    # steepest (as in the metadata test below); the roll by ~1e-13 deg
    slack = 1e-4
    assert tilt.max() <= 25.0 + slack and roll.min() >= -10.0 - slack and roll.max() <= 30.0 + slack
    # uniform over the cap: 1 - cos(tilt) is uniform on [0, 1 - cos 25 deg] (mean half, variance 1/12)
    u = (1 - np.cos(np.radians(tilt))) / (1 - np.cos(np.radians(25.0)))
    assert abs(u.mean() - 0.5) < 0.04 and abs(u.var() - 1 / 12) < 0.015
    r = (roll + 10.0) / 40.0
    assert abs(r.mean() - 0.5) < 0.04 and abs(r.var() - 1 / 12) < 0.015
    # the sampler's own record of each draw is what the pose shows
    drawn = np.array([[s.cone.cone_deg, s.cone.roll_deg] for s in map(generator.scene, range(50))])
    np.testing.assert_allclose(drawn, places[:50], rtol=0, atol=slack)


def test_uniform_stays_the_default_and_draws_what_it_always_drew(spacecraft):
    default, cone = (
        Generator(spacecraft, load_config(), 2),
        Generator(spacecraft, load_config(overrides=CONE), 2),
    )
    for i in range(20):
        a, b = default.scene(i), cone.scene(i)
        assert a.cone is None and "cone" not in a.to_dict()
        # only the attitude moves: the pose stream is the attitude's own
        assert a.target.t == b.target.t and a.sun == b.sun and a.background == b.background
    tilts = [
        corridor_place(default.scene(i).target.R_mat, default.scene(i).target.t_vec)[0] for i in range(200)
    ]
    assert max(tilts) > 90.0  # a uniform attitude leaves any cone


def test_a_cone_dataset_logs_its_place_in_the_corridor_in_metadata(tmp_path: Path):
    out = render_dataset(tmp_path / "cone", n=6, seed=4, overrides=CONE)
    rows = list(csv.DictReader((out / "metadata.csv").open()))
    assert len(rows) == 6 and {"pose_cone_deg", "pose_roll_deg"} <= set(rows[0])
    for row in rows:
        chunk = out / row["split"] / f"{int(row['scene_id']):06d}"
        gt = json.loads((chunk / "scene_gt.json").read_text())[row["im_id"]][0]
        R = np.asarray(gt["cam_R_m2c"], dtype=np.float64).reshape(3, 3)
        t = np.asarray(gt["cam_t_m2c"], dtype=np.float64) / 1000.0
        tilt, roll = corridor_place(R, t)
        # the CSV holds the draw's float64 (repr), scene_gt.json R in full and t through mm (2 u64): M's
        # entries within a few tens of u64, so the tilt within sqrt(2 x 32 u64) rad = 5e-6 deg where arccos
        # is steepest (near 0), the roll (atan2 of quaternion entries, w^2 + z^2 = cos^2(tilt / 2) >= 0.95)
        # to ~1e-13 deg; a frame mix-up is degrees
        assert float(row["pose_cone_deg"]) == pytest.approx(tilt, abs=1e-4)
        assert float(row["pose_roll_deg"]) == pytest.approx(roll, abs=1e-4)
    res = CliRunner().invoke(main, ["validate", str(out)])
    assert res.exit_code == 0, res.output


@pytest.mark.parametrize(
    "pose, message",
    [
        ({"distribution": "tumble"}, "pose.distribution must be one of uniform, cone, got 'tumble'"),
        ({"max_angle_deg": 200.0}, r"pose.max_angle_deg must lie in \[0, 180\], got 200.0"),
        ({"roll_deg": [30.0, -30.0]}, "pose.roll_deg must be"),
        ({"roll_deg": [0.0, 270.0]}, "pose.roll_deg must lie within"),
        ({"nominal": [0.0, 0.0, 0.0, 0.0]}, "pose.nominal must be a non-zero quaternion"),
        ({"nominal": [1.0, 0.0, 0.0]}, "pose.nominal must be a non-zero quaternion"),
    ],
)
def test_a_bad_pose_table_is_named(pose, message):
    with pytest.raises(ScgenError, match=message):
        load_config(overrides={"pose": pose})
