"""Rendezvous sequences as rendered frames: the labelled poses move as the labelled rates say, a surface
point's xyz label lands where that motion takes it, whole sequences go to one split, and a sequence render
validates with both backends (the physics of the trajectories themselves: test_orbit_dynamics.py)."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image
from scipy.spatial.transform import Rotation

from scgen import Generator
from scgen.cli import main
from scgen.dataset.validate import check_sequences
from scgen.errors import ScgenError
from scgen.scenes import load_config
from scgen.scenes.attitude import nominal_rotation, ray_rotation
from scgen.scenes.motion.orbit import PROFILES, R_EARTH, hcw_acceleration, mean_motion
from scgen.scenes.motion.sequence import POINTING_MODES, draw_sequence, minimal_rotation
from scgen.scenes.motion.tumble import ATTITUDE_MODES, mass_properties


def sequence_generator(**sequence: Any) -> Generator:
    """The bundled target, 160x120, with a `[sequence]` table of these keys."""
    return Generator.load(overrides={"sequence": sequence}, resolution=(160, 120), backend="mitsuba",
                          quality="draft")  # fmt: skip


@pytest.mark.parametrize("pointing", ["target", "fixed"])
@pytest.mark.parametrize("profile", list(PROFILES))
def test_consecutive_poses_differ_by_the_labelled_motion(profile: str, pointing: str):
    """Between frames dt apart, t moves by the trapezoid of its labelled rate and R turns by the rotation of
    the mean labelled angular velocity (dR/dt = [w]x R), for every profile and attitude mode."""
    dt = 0.5
    gen = sequence_generator(frames=20, dt_s=dt, profile_probs={profile: 1.0}, pointing=pointing,
                             rate_deg=[3.0, 5.0])  # fmt: skip
    seen = set()
    for s in range(12):
        specs = gen.sequence(s)
        seen.add(specs[0].sequence.attitude)
        t = np.array([sp.target.t for sp in specs])
        R = np.array([sp.target.R_mat for sp in specs])
        v = np.array([sp.sequence.velocity for sp in specs])
        w = np.array([sp.sequence.angular_velocity for sp in specs])
        assert [sp.sequence.frame for sp in specs] == list(range(20))
        assert {sp.index // 20 for sp in specs} == {s}
        # the trapezoid's error is dt^3/12 |t'''|: at 5 deg/s and the profiles' speeds, < 1e-7 m of a
        # 0.2 m model (measured 7.7e-8 at most); a wrong sign or frame gives ~dt |v|, 1e-4 to 1e-2 m
        moved = t[1:] - t[:-1] - dt * 0.5 * (v[1:] + v[:-1])
        assert np.abs(moved).max() < 1e-6 + 1e-4 * dt * np.abs(v).max()
        turned = Rotation.from_matrix(R[1:] @ np.swapaxes(R[:-1], 1, 2)).as_rotvec()
        # the mean rate's error is O(dt^3 |w'| |w|): < 1e-6 rad at these rates (measured 7.0e-7 at most),
        # the tracking camera's discrete transport adding a roll of the same order; leaving out LVLH's
        # turn (n ~ 1.1e-3 rad/s) or the camera's would miss by > 5e-4 rad
        assert np.abs(turned - dt * 0.5 * (w[1:] + w[:-1])).max() < 2e-5
    assert seen == set(ATTITUDE_MODES)  # 12 sequences draw all four modes (a fixed seed: checked here)


@pytest.mark.parametrize("pointing", POINTING_MODES)
def test_the_chasers_own_state_is_the_one_its_frames_move_by(pointing: str):
    """What a navigation filter reads of the chaser (cam_q*, cam_w*, thrust_*): the camera's attitude in
    LVLH turns between frames by its labelled rate (camera axes: R_LC(t + dt) = R_LC(t) exp(dt w)), and
    the labelled thrust, plus the free HCW acceleration, is the acceleration of the chaser's own track
    (the centre of mass relative to the camera, -R_LC (t + R c) in LVLH: its second difference)."""
    dt = 0.5
    for profile in PROFILES:
        gen = sequence_generator(frames=12, dt_s=dt, profile_probs={profile: 1.0}, pointing=pointing)
        c = mass_properties([mesh for _, mesh in gen.model.parts]).centre_of_mass
        frames = [sp.sequence for sp in gen.sequence(0)]
        R_lc = Rotation.from_quat([np.roll(f.camera_attitude, -1) for f in frames]).as_matrix()
        w = np.array([f.camera_rate for f in frames])
        turned = Rotation.from_matrix(np.swapaxes(R_lc[:-1], 1, 2) @ R_lc[1:]).as_rotvec()
        # the mean rate's error is O(dt^3 |w'| |w|) and the transport's discrete steps of the same order:
        # < 1e-8 rad at these rates; a rate in LVLH axes, or of the wrong sign, misses by ~dt |w|
        assert np.abs(turned - dt * 0.5 * (w[1:] + w[:-1])).max() < 1e-6 + 1e-3 * dt * np.abs(w).max()
        n = mean_motion(R_EARTH + 1e3 * frames[0].altitude_km)
        com = np.array([sp.target.t_vec + sp.target.R_mat @ c for sp in gen.sequence(0)])
        r = -np.einsum("kij,kj->ki", R_lc, com)  # the chaser from the target, LVLH, model metres
        accel = (r[2:] - 2 * r[1:-1] + r[:-2]) / dt**2
        v = (r[2:] - r[:-2]) / (2 * dt)
        thrust = np.array([f.thrust for f in frames])[1:-1]
        # the differences' errors are dt^2 |r'''| / 6 and dt^2 |r''''| / 12: at n ~ 1e-3 rad/s, ~1e-9 of the
        # HCW terms; a thrust of the wrong sign or scale misses by its own size
        free = hcw_acceleration(r[1:-1], v, n)
        size = np.abs(free).max() + np.abs(thrust).max()
        assert np.abs(accel - free - thrust).max() <= 1e-6 * size + 1e-15, profile


def test_a_frame_is_the_same_whatever_frames_are_asked():
    """Frame k of sequence s from a fresh generator, asked alone, equals the one of a pass over all."""
    gen = sequence_generator(frames=6, dt_s=4.0, attitude_probs={"tumble": 1.0})
    every = [gen.scene(i).to_dict() for i in range(18)]
    assert (
        sequence_generator(frames=6, dt_s=4.0, attitude_probs={"tumble": 1.0}).scene(15).to_dict()
        == every[15]
    )
    assert every[6]["sequence"]["sequence"] == 1 and every[6]["sequence"]["frame"] == 0


def test_xyz_label_of_a_surface_point_projects_where_the_motion_says():
    """A visible surface point of frame 0 (its xyz label X), moved dt by the labelled rates, projects to
    a pixel of frame 1 whose xyz label is X again (within the pixel's footprint on the target)."""
    dt = 6.0
    hold = {"vbar_hold": {"distance_m": [4.0, 4.5]}}
    gen = sequence_generator(frames=2, dt_s=dt, profile_probs={"vbar_hold": 1.0}, profiles=hold,
                             attitude_probs={"tumble": 1.0}, rate_deg=[4.0, 5.0], spacecraft_diameter_m=2.0,
                             pointing_error_deg=0.0)  # fmt: skip
    with gen:
        a, b = gen.sample(0), gen.sample(1)
    K = a.spec.camera.K_mat
    va, vb = a.annotation.mask_visib, b.annotation.mask_visib
    assert va.sum() > 300 and vb.sum() > 300  # the target fills a good part of the 160x120 frame
    fa, fb = a.spec.sequence, b.spec.sequence
    w = 0.5 * (np.array(fa.angular_velocity) + np.array(fb.angular_velocity))
    v = 0.5 * (np.array(fa.velocity) + np.array(fb.velocity))
    turn = Rotation.from_rotvec(dt * w).as_matrix()
    Ra, ta = a.spec.target.R_mat, a.spec.target.t_vec
    rows, cols = np.nonzero(va)
    X = a.annotation.xyz[rows, cols]  # model frame
    Xa = X @ Ra.T + ta
    Xb = (Xa - ta) @ turn.T + ta + dt * v  # rigid motion about the model origin, by the labelled rates
    uv = Xb @ K.T
    u, vv = np.round(uv[:, 0] / uv[:, 2]).astype(int), np.round(uv[:, 1] / uv[:, 2]).astype(int)
    inside = (u >= 0) & (u < vb.shape[1]) & (vv >= 0) & (vv < vb.shape[0])
    hit = inside.copy()
    hit[inside] = vb[vv[inside], u[inside]]
    assert hit.mean() > 0.8  # the rest: turned out of view, or behind another part
    err = np.linalg.norm(b.annotation.xyz[vv[hit], u[hit]] - X[hit], axis=1)
    footprint = Xb[hit, 2] / K[0, 0]  # a pixel's size on a surface facing the camera (m)
    # rounding to the nearest pixel moves <= 0.71 px; oblique surfaces stretch a pixel: the median tests
    # (measured 0.59, against 5.5 for the point's own pixel in frame 1; 94 % of the points hit)
    assert np.median(err / footprint) < 1.5
    # the motion is real: the points moved by pixels, so the same pixel of frame 1 holds another point
    moved_px = np.hypot(uv[:, 0] / uv[:, 2] - cols, uv[:, 1] / uv[:, 2] - rows)
    assert np.median(moved_px) > 2.0
    assert (
        np.median(np.linalg.norm(b.annotation.xyz[rows[hit], cols[hit]] - X[hit], axis=1) / footprint) > 2.0
    )


def _rows(root: Path) -> list[dict[str, str]]:
    with open(root / "metadata.csv", newline="") as f:
        return list(csv.DictReader(f))


def render_sequences(out: Path, backend: str, n: int, frames: int, *extra: str) -> None:
    config = out.parent / f"{out.name}.toml"
    config.write_text(f"[sequence]\nframes = {frames}\ndt_s = 3.0\nspacecraft_diameter_m = 2.0\n")
    args = ["render", "--n", str(n), "--out", str(out), "--config", str(config), "--backend", backend,
            "--resolution", "64x48", "--quality", "draft", "--workers", "1", "--quiet", *extra]  # fmt: skip
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output


def test_whole_sequences_go_to_one_split_and_are_bop_scenes(tmp_path: Path):
    """Each sequence is one BOP scene (scene_id = sequence id) in one split, its frames consecutive ids;
    the split is planned over sequences, so no sequence has frames in two splits."""
    gen = sequence_generator(frames=4, dt_s=1.0)
    from scgen.run.runner import RenderJob, make_plan

    for split_by in ("factors", "random"):
        plan = make_plan(RenderJob(out=tmp_path / "x", n=40, seed=5, backend="mitsuba", split_by=split_by,
                                   overrides={"sequence": {"frames": 4, "dt_s": 1.0}}))  # fmt: skip
        by_sequence: dict[int, set[str]] = {}
        for spec, split in zip(plan.specs, plan.splits, strict=True):
            by_sequence.setdefault(spec.sequence.sequence, set()).add(split)
        assert len(by_sequence) == 40 and all(len(s) == 1 for s in by_sequence.values())
        assert {s for ss in by_sequence.values() for s in ss} == {"train", "val", "test"}
    assert gen.frames == 4
    out = tmp_path / "mitsuba"
    render_sequences(out, "mitsuba", 3, 2, "--split", "0.34,0.33,0.33", "--split-by", "random")
    rows = _rows(out)
    assert [int(r["sample_id"]) for r in rows] == list(range(6))
    for r in rows:
        assert int(r["scene_id"]) == int(r["sequence_id"]) == int(r["sample_id"]) // 2
        assert int(r["frame"]) == int(r["sample_id"]) % 2 and float(r["time_s"]) == 3.0 * int(r["frame"])
        scene = out / r["split"] / f"{int(r['scene_id']):06d}"
        assert (scene / "scene_gt.json").is_file()
    assert len({(r["sequence_id"], r["split"]) for r in rows}) == 3


@pytest.mark.parametrize("backend", ["mitsuba", "blender"])
def test_a_sequence_render_validates(tmp_path: Path, backend: str):
    """`scgen validate` passes on 2 sequences x 3 frames (64x48, draft)."""
    out = tmp_path / backend
    render_sequences(out, backend, 2, 3)
    result = CliRunner().invoke(main, ["validate", str(out), "--quiet", "--workers", "1"])
    assert result.exit_code == 0, result.output
    rows = _rows(out)
    assert len(rows) == 6 and {r["sequence_id"] for r in rows} == {"0", "1"}
    result = CliRunner().invoke(main, ["stats", str(out)])
    assert result.exit_code == 0, result.output
    assert sum(f"{s}: 1 sequences, 3 frames" in result.output for s in ("train", "val", "test")) == 2


def test_validate_names_a_sequence_in_two_splits_and_a_misplaced_frame():
    """check_sequences reads metadata.csv's rows: a sequence with frames in two splits, a frame whose
    sequence, scene or time is not the one its id gives."""
    rows = [{"sample_id": str(i), "sequence_id": str(i // 3), "scene_id": str(i // 3), "frame": str(i % 3),
             "time_s": repr(2.0 * (i % 3)), "split": "train"} for i in range(6)]  # fmt: skip
    sequence = {"count": 2, "frames": 3, "dt_s": 2.0}
    assert check_sequences(rows, sequence) == []
    rows[4]["split"] = "test"
    rows[2]["scene_id"] = "1"
    rows[5]["time_s"] = "4.5"
    problems = check_sequences(rows, sequence)
    assert problems == [
        "sample 2: sequence 0, frame 2, scene 1; its id gives sequence and scene 0, frame 2",
        "sample 5: time_s 4.5 is not frame 2 x dt 2.0",
        "sequence 1: frames in test, train",
    ]


def test_independent_configs_have_no_sequence_table_and_bad_keys_are_named():
    """Without a [sequence] table the resolved config holds none (the bytes of every existing seed stay);
    a bad sequence key is named."""
    assert "sequence" not in load_config()
    for table, words in (({"frame": 3}, "sequence.frame"), ({"pointing": "sun"}, "sequence.pointing"),
                         ({"profile_probs": {"hover": 1.0}}, "hover"),
                         ({"profiles": {"flyby": {"speed": [1, 2]}}}, "speed")):  # fmt: skip
        with pytest.raises(ScgenError, match=words):
            load_config(overrides={"sequence": table})


def test_the_example_config_gives_the_sequences_its_docs_say():
    """examples/rendezvous.toml (the docs' runnable example): 60 frames 5 s apart, its approaches closing."""
    gen = Generator.load(config=Path(__file__).parents[1] / "examples" / "rendezvous.toml")
    assert gen.frames == 60
    specs = gen.sequence(0)
    assert [s.sequence.time_s for s in specs[:3]] == [0.0, 5.0, 10.0]
    approaches = [
        f for f in (gen.sequence(s) for s in range(6)) if f[0].sequence.profile == "corridor_approach"
    ]
    assert approaches  # 40 % of the sequences: seed 0 draws 4 of 6
    for frames in approaches:
        assert frames[-1].sequence.range_m < frames[0].sequence.range_m


def test_the_strip_config_is_the_approach_its_caption_says():
    """examples/approach.toml (docs/sequence_strip.jpg, `make figures`): sequence 1 is 12 frames 10 s apart
    of a tumbling target approached along the corridor from 20-25 m at 0.1-0.15 m/s."""
    gen = Generator.load(config=Path(__file__).parents[1] / "examples" / "approach.toml")
    frames = gen.sequence(1)
    assert len(frames) == 12 and [f.sequence.time_s for f in frames[:2]] == [0.0, 10.0]
    kinds = {(f.sequence.profile, f.sequence.attitude) for f in frames}
    assert kinds == {("corridor_approach", "tumble")}
    ranges = [f.sequence.range_m for f in frames]  # closing at 0.1-0.15 m/s for 110 s: 11-16.5 m nearer
    assert 19.0 < ranges[0] < 26.0 and all(b <= a for a, b in zip(ranges, ranges[1:], strict=False))
    assert ranges[0] - ranges[-1] > 5.0


def test_preview_of_a_sequence_writes_its_frames_as_a_gif(tmp_path: Path):
    """`scgen preview --sequence K` animates every frame of sequence K; without a [sequence] table it is
    one line naming what is missing."""
    config = tmp_path / "s.toml"
    config.write_text("[sequence]\nframes = 3\ndt_s = 10.0\n")
    args = ["preview", "--out", str(tmp_path / "pv"), "--backend", "mitsuba", "--resolution", "64x48"]
    result = CliRunner().invoke(main, [*args, "--config", str(config), "--sequence", "1"])
    assert result.exit_code == 0, result.output
    with Image.open(tmp_path / "pv" / "sequence_1.gif") as gif:
        assert gif.n_frames == 3
    assert (tmp_path / "pv" / "sequence_1.png").is_file()
    result = CliRunner().invoke(main, [*args, "--sequence", "0"])
    assert result.exit_code == 1 and "[sequence] table" in result.output


def test_motion_blur_is_the_target_centres_image_motion_over_the_exposure():
    """Where the camera models motion blur, a frame's blur is the target centre's image velocity times the
    exposure time: its length and direction match the centre's projected displacement over a short dt,
    scaled to the exposure (an undrawn blur, whatever the camera's motion_blur_prob draws elsewhere)."""
    dt = 0.2
    gen = sequence_generator(frames=2, dt_s=dt, profile_probs={"flyby": 1.0}, pointing="fixed")
    exposure = gen.cfg["camera"]["sensor"]["exposure_time_s"]
    assert gen.cfg["camera"]["optics"]["motion_blur_prob"] > 0
    for s in range(4):
        a, b = gen.sequence(s)
        uv = a.camera.project(np.array([a.target.t, b.target.t]))
        shift = (uv[1] - uv[0]) * exposure / dt  # px during the exposure, by finite differences
        assert a.imaging.motion_blur_px == pytest.approx(np.hypot(*shift), rel=1e-3, abs=1e-8)
        assert a.imaging.motion_blur_px > 0
        angle = np.degrees(np.arctan2(shift[1], shift[0])) % 180.0
        assert min(abs(a.imaging.motion_blur_deg - angle), 180 - abs(a.imaging.motion_blur_deg - angle)) < 0.1


# ---------------------------------------------------------------------------------------------------------
# initial_attitude = "pose": frame 0 drawn from the [pose] table, as an independent sample is

CONE = {"distribution": "cone", "max_angle_deg": 20.0, "roll_deg": [-20.0, 20.0]}
# roundoff bounds below count U = 2^-53 = 1.1e-16, the relative error of one float64 operation


def pose_generator(pose: dict[str, Any] | None = None, **sequence: Any) -> Generator:
    """sequence_generator's, with a `[pose]` table too (the cone above unless given)."""
    overrides = {"sequence": sequence, "pose": CONE if pose is None else pose}
    return Generator.load(overrides=overrides, resolution=(160, 120), backend="mitsuba", quality="draft")


def cone_place(R: np.ndarray, ray: np.ndarray, pose: dict[str, Any]) -> tuple[float, float]:
    """(tilt, roll) in degrees of the egocentric R seen along `ray`, in the corridor of a cone `pose` table:
    the allocentric attitude ray_rotation(ray)^T R is Rz(roll) Rtilt R_nominal (scgen.scenes.attitude), so
    with R_rel = that times R_nominal^T, w = R_rel^T z = Rtilt^T z gives the tilt (the angle of w from z)
    and Rtilt (the smallest rotation taking w onto z), and R_rel Rtilt^T = Rz(roll) the roll."""
    rel = ray_rotation(ray).T @ R @ nominal_rotation(pose).T
    w = rel[2]  # R_rel^T z
    tilt = minimal_rotation(w, np.array([0.0, 0.0, 1.0]))
    twist = rel @ tilt.T
    return (
        float(np.degrees(np.arctan2(np.hypot(w[0], w[1]), w[2]))),
        float(np.degrees(np.arctan2(twist[1, 0], twist[0, 0]))),
    )


def test_initial_attitude_pose_puts_frame_0_in_the_cone():
    """With initial_attitude = "pose" and a cone [pose] table, frame 0 of every sequence (any profile, any
    attitude motion) is seen along the ray to the target's centre of mass at the tilt and roll its cone
    draw says, so inside the cone; and 50 sequences fill it."""
    gen = pose_generator(frames=2, dt_s=5.0, initial_attitude="pose")
    props = mass_properties([mesh for _, mesh in gen.model.parts])
    places, modes = [], set()
    for s in range(50):
        frame0 = gen.sequence(s)[0]
        modes.add(frame0.sequence.attitude)
        com = np.asarray(frame0.target.t) + frame0.target.R_mat @ props.centre_of_mass
        tilt, roll = cone_place(frame0.target.R_mat, com, gen.cfg["pose"])
        drawn = draw_sequence(gen.seed, s, gen.cfg["sequence"], props, gen.cfg["pose"]).cone
        # R passes from the draw to the label through ~50 float64 roundings (the ray's rotation, the
        # quaternion q0 and back, R_IL^T R_IL R_LB, R_LC^T R_LB, the centre-of-mass ray recomputed from the
        # track, this decomposition), each moving it by <= a few U (1.1e-16): < 1e-13 rad in all, so
        # 1e-10 deg (1.7e-12 rad) is met with a margin of 10 and a wrong frame misses by degrees
        assert abs(tilt - drawn.cone_deg) < 1e-10 and abs(roll - drawn.roll_deg) < 1e-10
        places.append((tilt, roll))
    assert modes == set(ATTITUDE_MODES)
    tilt, roll = np.array(places).T
    assert tilt.max() <= 20.0 + 1e-10 and np.abs(roll).max() <= 20.0 + 1e-10
    # cos(tilt) is uniform over [cos 20, 1]: P(tilt > 10) = (cos 10 - cos 20) / (1 - cos 20) = 0.75, so 50
    # draws give 37 +- 3 above half the angle (>= 25 is 4 standard deviations down); roll is uniform
    # over +-20, each half-range's outer half drawn with probability 1/4 a sequence
    assert (tilt > 10.0).sum() >= 25
    assert roll.max() > 10.0 and roll.min() < -10.0


def test_an_lvlh_hold_on_the_corridor_stays_where_frame_0_put_it():
    """lvlh_hold on a corridor approach with the camera tracking the target: the approach line is fixed in
    LVLH and so is the target, so the tracking camera never turns (R_LC constant) and R = R_LC^T R_LB and
    the centre of mass's ray are the same at every frame. Seen along that ray, every frame is frame 0
    (within roundoff); seen along the ray to the model origin (an independent sample's allocentric frame,
    posenet's), the tilt moves by at most the angle between the two rays, <= asin(|c| / |com|)."""
    frames = 30
    gen = pose_generator(frames=frames, dt_s=10.0, initial_attitude="pose", pointing="target",
                         profile_probs={"corridor_approach": 1.0},
                         attitude_probs={"lvlh_hold": 1.0})  # fmt: skip
    props = mass_properties([mesh for _, mesh in gen.model.parts])
    c = props.centre_of_mass
    closed = 0.0
    for s in range(12):
        specs = gen.sequence(s)
        R = np.array([sp.target.R_mat for sp in specs])
        t = np.array([sp.target.t for sp in specs])
        com = t + R @ c
        allo = np.array([ray_rotation(x).T @ r for x, r in zip(com, R, strict=True)])
        # frame to frame, R and the ray differ only by roundoff: R_IL^T (R_IL R_LB) (<= 12 U a step), the
        # tracking camera's transport over frames - 1 steps (each an identity or a turn by the ~4 U its
        # two rays' rounding differ by, plus a product's 6 U) and the ray's rotation (a few U): under
        # 29 x 12 U + 30 U ~ 5e-14 rad at frame 29; 1e-12 rad bounds it with a margin of 20, while the
        # orbit's turn of LVLH in a hold left out would move R by n dt ~ 1e-2 rad a frame
        drift = Rotation.from_matrix(allo @ allo[0].T).magnitude()
        assert drift.max() < 1e-12
        tilt0, _ = cone_place(R[0], com[0], gen.cfg["pose"])
        cross = np.linalg.norm(np.cross(t, com), axis=1)
        apart = np.arctan2(cross, np.sum(t * com, axis=1))  # the angle between the two rays
        assert np.all(apart <= np.arcsin(np.linalg.norm(c) / np.linalg.norm(com, axis=1)) + 1e-12)
        for k in range(frames):
            # the line of sight in the target's frame moves by the angle between the rays, exactly (a
            # rotation keeps angles): the tilt, an angle from the nominal line, moves by at most that
            tilt, _ = cone_place(R[k], t[k], gen.cfg["pose"])
            assert abs(tilt - tilt0) <= np.degrees(apart[k]) + 1e-10
            assert tilt <= 20.0 + np.degrees(apart[k]) + 1e-10
        closed += specs[0].sequence.range_m - specs[-1].sequence.range_m
    assert closed > 12 * 3.0  # the approaches move (0.02-0.2 m/s for 290 s): the test is not of a hold


def test_initial_attitude_uniform_is_the_draw_without_the_key_and_pose_changes_only_q0():
    """initial_attitude = "uniform" (the default) leaves every frame what a config without the key gives;
    "pose" draws from its own stream, so it changes the attitude at t = 0 and nothing else drawn."""
    base = {"frames": 4, "dt_s": 3.0, "rate_deg": [1.0, 4.0]}
    absent, uniform = pose_generator(**base), pose_generator(initial_attitude="uniform", **base)
    posed = pose_generator(initial_attitude="pose", **base)
    props = mass_properties([mesh for _, mesh in absent.model.parts])
    for s in range(8):
        assert [f.to_dict() for f in uniform.sequence(s)] == [f.to_dict() for f in absent.sequence(s)]
        a = draw_sequence(absent.seed, s, absent.cfg["sequence"], props, absent.cfg["pose"])
        b = draw_sequence(posed.seed, s, posed.cfg["sequence"], props, posed.cfg["pose"])
        assert a.cone is None and b.cone is not None
        assert b.attitude.q0 != a.attitude.q0
        assert b.profile == a.profile
        for field in ("altitude_m", "roll_rad", "sky_longitude", "sky_roll", "earth_spin_deg"):
            assert getattr(b, field) == getattr(a, field)
        assert np.array_equal(b.error, a.error) and b.sun == a.sun
        assert (b.attitude.mode, b.attitude.omega0) == (a.attitude.mode, a.attitude.omega0)


def test_a_bad_initial_attitude_is_one_line_naming_it():
    """A bad sequence.initial_attitude is refused in one line naming the key and the value."""
    bad = r"^sequence\.initial_attitude must be one of uniform, pose, got 'cone'$"
    with pytest.raises(ScgenError, match=bad):
        load_config(overrides={"sequence": {"initial_attitude": "cone"}})
    with pytest.raises(ScgenError, match="sequence.initial_attitude' must be a string"):
        load_config(overrides={"sequence": {"initial_attitude": 1}})
