"""`posenet eval` on a split of rendezvous sequences: per-sequence error along time and the frame-to-frame
jitter of the estimate beside the truth's. The jitter is checked on physics (zero for motion at constant
velocity and rate, the noise's known RMS for white noise) and end to end on a real sequence render."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from posenet_helpers import calibrate_untrained, tiny_pose_checkpoint
from scipy.spatial.transform import Rotation

from posenet.cli import main
from posenet.evaluation.sequences import rotation_jitter_deg, sequence_figures, translation_jitter_m
from scgen.dataset.layout import read_metadata
from scgen.generator import Generator
from scgen.io import SequenceFrame, read_sequence_frames
from tests.conftest import SEQUENCE

RNG = np.random.default_rng(0)


RATE_DEG_S = np.array([1.0, -2.0, 0.5])  # constant_motion's rate


def constant_motion(n: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """n poses at constant velocity and constant rate in the camera frame: R_k = exp(k dt [w]x) R_0."""
    t = np.array([0.1, -0.2, 5.0]) + np.outer(np.arange(n) * dt, [0.02, 0.01, -0.05])
    turn = Rotation.from_rotvec(np.radians(RATE_DEG_S) * dt)
    R0 = Rotation.from_rotvec([0.3, 1.2, -0.4])
    R = np.array([(turn**k * R0).as_matrix() for k in range(n)])
    return R, t


def rounding_floor(t: np.ndarray, dt: float) -> tuple[float, float]:
    """The jitter (m, deg) float64 leaves of constant_motion(len(t), dt), whose exact jitter is 0, for `t`
    its translations (or a copy shifted along time): each t_k takes up to 3 roundings (a product, a sum, a
    shift), ~3 u64 |t|, and a second difference four of them: 16 u64 max|t|. Each R_k is scipy's rotation of
    the vector k dt w (its angle up to len(t) dt |w|) through sin and cos, good to ~4 u64 of that angle, and
    D_k D_{k-1}^T combines four: 16 u64 x the largest angle (at least 1 rad), in radians."""
    u64 = 2**-53
    turned = float(np.radians(np.linalg.norm(RATE_DEG_S))) * len(t) * dt
    return 16 * u64 * float(np.linalg.norm(t, axis=1).max()), float(np.degrees(16 * u64 * max(turned, 1.0)))


def test_constant_motion_has_no_jitter_and_white_noise_has_its_rms():
    """Second differences vanish at constant velocity and rate; white noise of σ per axis gives
    sqrt(1 + 4 + 1) σ per axis, sqrt(18) σ over three axes, for translation and (to first order) rotation."""
    n, sigma_t, sigma_r = 2000, 0.01, np.radians(0.5)
    R, t = constant_motion(n, 3.0)
    ok = np.ones(n, dtype=bool)
    floor_t, floor_deg = rounding_floor(t, 3.0)
    assert translation_jitter_m(t, ok) <= floor_t and rotation_jitter_deg(R, ok) <= floor_deg
    noisy_t = t + RNG.normal(0.0, sigma_t, t.shape)
    noisy_R = Rotation.from_rotvec(RNG.normal(0.0, sigma_r, (n, 3))).as_matrix() @ R
    # the RMS of n - 2 second differences: |e|^2 is 6 sigma^2 chi2(3) (relative variance 2/3), neighbours
    # correlate (rho = -2/3, 1/6: the variance of the mean x 1 + 2 (4/9 + 1/36)), so the mean square spreads
    # by sqrt(2/3 x 1.94 / 1998) = 2.5 % and the RMS by half that: 5 % is 3.9 of its sigma (the seed fixes it)
    assert translation_jitter_m(noisy_t, ok) == pytest.approx(np.sqrt(18) * sigma_t, rel=0.05)
    assert rotation_jitter_deg(noisy_R, ok) == pytest.approx(np.degrees(np.sqrt(18) * sigma_r), rel=0.05)
    # a failed frame drops the triples it is in; with none left there is no figure
    ok[1] = False
    assert (
        translation_jitter_m(noisy_t[:3], ok[:3]) is None and rotation_jitter_deg(noisy_R[:3], ok[:3]) is None
    )
    assert translation_jitter_m(t, ok) <= floor_t


def test_sequence_figures_orders_frames_and_summarises_each_sequence():
    """Records in any order become per-sequence series in time order, with medians, maxima, failures."""
    R, t = constant_motion(6, 2.0)
    frames = {(7, 70 + k): SequenceFrame(7, k, 2.0 * k) for k in range(6)}
    truth = {(7, 70 + k): (R[k], t[k]) for k in range(6)}
    records = []
    for k in (3, 0, 4, 1, 2):  # out of time order on purpose; frame 5 not evaluated (target not visible)
        failed = k == 4
        pose = {"R": R[k].ravel().tolist(), "t": (t[k] + [0.0, 0.0, 0.01 * k]).tolist()}
        errors = {"re_deg": float(k), "te_m": 0.01 * k}
        if failed:
            pose, errors = {"R": None, "t": None}, {"re_deg": np.inf, "te_m": np.inf}
        records.append({"scene_id": 7, "im_id": 70 + k, **pose, **errors})
    (fig,) = sequence_figures(records, truth, frames)
    assert (fig["sequence_id"], fig["frames"], fig["evaluated"], fig["failed"]) == (7, 6, 5, 1)
    assert [s["frame"] for s in fig["series"]] == list(range(6))
    assert [s["time_s"] for s in fig["series"]] == [0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
    assert fig["series"][4]["re_deg"] is None and fig["series"][5]["te_m"] is None
    assert fig["series"][3]["te_m"] == 0.01 * 3  # the record's own te_m
    assert (fig["re_deg_median"], fig["re_deg_max"]) == (1.5, 3.0)
    floor_t, floor_deg = rounding_floor(t + [0.0, 0.0, 0.05], 2.0)  # the estimate's largest |t| too
    assert fig["jitter_t_m"] <= floor_t  # a depth error growing linearly is still constant velocity
    assert fig["jitter_t_m_truth"] <= floor_t and fig["jitter_rot_deg_truth"] <= floor_deg


def test_independent_frames_have_no_sequence_frames(tmp_path: Path):
    (tmp_path / "metadata.csv").write_text("sample_id,split,scene_id,im_id\n0,train,0,0\n")
    assert read_sequence_frames(tmp_path) == {} and read_sequence_frames(tmp_path / "none") == {}


def labelled_jitter_bound(sequence: int) -> tuple[float, float]:
    """Bounds on the truth's jitter (m, deg) of sequence `sequence` of conftest's sequence render, from the
    motion scgen labels its frames with (SequenceFrame: v = dt/dt, w with dR/dt = [w]x R, camera axes).
    Over the two steps around frame k, the trapezoid rule gives t_{k+1} - 2 t_k + t_{k-1} =
    dt (v_{k+1} - v_{k-1}) / 2 up to dt^4 |t^(4)| / 12, and the angle of D_k D_{k-1}^T likewise
    dt |w_{k+1} - w_{k-1}| / 2 up to that and the turn's change of axis (dt |w| / 2 of it): with rates up
    to the tumble's 5 deg/s and dt = 3 s, under 0.13 of the figure, so twice it bounds the truth. A motion
    with no change (a hold) leaves the labels' rounding: 4 float64 roundings of t (8 u64 |t|), and of R's
    entries through four products (64 u64 rad)."""
    u64 = 2**-53
    specs = Generator.load(seed=0, overrides={"sequence": SEQUENCE}, resolution=(64, 48)).sequence(sequence)
    dt = SEQUENCE["dt_s"]
    t_max = max(float(np.linalg.norm(s.target.t)) for s in specs)

    def rms_half_step(x: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.sum((dt * (x[2:] - x[:-2]) / 2) ** 2, axis=1))))

    v = rms_half_step(np.array([s.sequence.velocity for s in specs]))
    w = rms_half_step(np.array([s.sequence.angular_velocity for s in specs]))
    return 2 * v + 8 * u64 * t_max, float(np.degrees(2 * w + 64 * u64))


def test_eval_on_a_sequence_split_reports_each_sequence(
    sequence_dataset: Path, tmp_path_factory: pytest.TempPathFactory, tmp_path: Path
):
    """A tiny checkpoint on a real render: one table row and one `sequences` entry per sequence of the
    split, its frames in time order, and the truth's jitter (the rendered dynamics) far below the
    estimate's."""
    ckpt = tiny_pose_checkpoint(sequence_dataset, tmp_path_factory)
    out = tmp_path / "eval.json"
    args = ["eval", "--data", sequence_dataset, "--ckpt", ckpt, "--split", "train", "--json", out]
    res = CliRunner().invoke(main, [str(a) for a in [*args, "--workers", 0]])
    assert res.exit_code == 0, res.output
    rows = [r for r in read_metadata(sequence_dataset) if r["split"] == "train"]
    seqs = sorted({int(r["sequence_id"]) for r in rows})
    assert len(seqs) == 2
    lines = res.output.splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.startswith("sequence "))
    assert "t jitter (m)" in lines[head] and "rot jitter truth (deg)" in lines[head]
    assert lines[head + 2 + len(seqs)].startswith("re, te: error over the frames")
    assert [int(ln.split()[0]) for ln in lines[head + 2 : head + 2 + len(seqs)]] == seqs
    figures = json.loads(out.read_text())["sequences"]
    assert [f["sequence_id"] for f in figures] == seqs
    frames, dt = SEQUENCE["frames"], SEQUENCE["dt_s"]
    for f in figures:
        assert f["frames"] == f["evaluated"] == frames and len(f["series"]) == frames
        assert [s["time_s"] for s in f["series"]] == [k * dt for k in range(frames)]
        errors = [s["re_deg"] for s in f["series"]]
        # np.median of the same floats (JSON keeps them: repr), an order-free middle pair's (a + b) / 2
        assert f["re_deg_median"] == np.median(errors) and f["re_deg_max"] == max(errors)
        t_bound, rot_bound = labelled_jitter_bound(f["sequence_id"])
        assert f["jitter_t_m_truth"] <= t_bound and f["jitter_rot_deg_truth"] <= rot_bound
        assert (
            f["jitter_t_m"] > 100 * f["jitter_t_m_truth"]
            and f["jitter_rot_deg"] > 100 * f["jitter_rot_deg_truth"]
        )


def test_eval_on_a_sequence_split_filters_and_smooths(
    sequence_dataset: Path, tmp_path_factory: pytest.TempPathFactory, tmp_path: Path
):
    """Without the checkpoint's calibrated noise, eval says how to get the navigation figures; with it
    (posenet calibrate on the test split), the per-frame, filtered and smoothed columns over every frame
    of the evaluated split: the filter poses no frame before a sequence's second (it starts at the first of
    two measurements that agree), the smoother, over the filter's own steps, that first one too, and only
    the filter and the smoother give a covariance to check the truth against."""
    ckpt = tmp_path / "last.pt"  # a copy: the shared checkpoint stays read-only, with no noise beside it
    shutil.copy(tiny_pose_checkpoint(sequence_dataset, tmp_path_factory), ckpt)
    noise = ckpt.with_name(ckpt.stem + ".noise.json")
    out = tmp_path / "eval.json"
    args = [
        "eval",
        "--data",
        sequence_dataset,
        "--ckpt",
        ckpt,
        "--split",
        "train",
        "--workers",
        0,
        "--json",
        out,
    ]
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 0 and "posenet calibrate --data DATASET" in res.output, res.output
    calibrate_untrained(sequence_dataset, ckpt)
    assert noise.is_file()
    res = CliRunner().invoke(main, [str(a) for a in [*args[:-2], "--json", tmp_path / "nav.json"]])
    assert res.exit_code == 0, res.output
    assert any(line.startswith("navigation ") and "filtered" in line for line in res.output.splitlines())
    nav = json.loads((tmp_path / "nav.json").read_text())["navigation"]
    frames = SEQUENCE["frames"] * 2  # the train split's two sequences
    assert {nav[c]["frames"] for c in ("per_frame", "filtered", "smoothed")} == {frames}
    assert nav["per_frame"]["posed"] == frames
    # online the filter poses from each sequence's second frame, the smoother from its first as well
    assert (
        0 < nav["filtered"]["posed"] <= frames - 2
        and nav["smoothed"]["posed"] == nav["filtered"]["posed"] + 2
    )
    assert nav["per_frame"]["in_3sigma_t"] is None and nav["filtered"]["in_3sigma_t"] is not None
    assert nav["noise"]["split"] == "test"
