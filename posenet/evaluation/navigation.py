"""The navigation filter scored along sequences: per-frame poses, the filter's and the smoother's, side by
side against scgen's exact trajectory.

`run_filter` feeds one sequence's per-frame poses (with their calibrated covariance,
posenet.navigation.noise) through the filter in time order, then the smoother; `navigation_figures`
scores any set of estimates over a sequence split, all frames counted (a frame without a pose fails ADD):

- ADD@0.1d (ADD-S for a symmetric object), the median rotation and translation errors over posed frames;
- jitter, the RMS second difference of the estimates over consecutive posed frames (as in
  posenet.evaluation.sequences), pooled over the sequences;
- the velocity dt/dt and angular velocity (camera axes, as metadata.csv labels them): the filter's own,
  and for per-frame poses their finite differences (central where both neighbours have a pose, else
  one-sided), the baseline a filter must beat;
- where an estimate has a covariance: the share of frames whose true error lies inside the 3-sigma
  ellipsoid (chi-square, 3 dof, probability 0.9973) of each block, and the mean NEES per block (3 if the
  covariance is right).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy.stats import chi2

from posenet.checkpoint import load_checkpoint
from posenet.config import config_from_dict
from posenet.data.layout import scan_split
from posenet.data.object_model import ObjectModel, load_object_model
from posenet.evaluation.metrics import add_error, adds_error
from posenet.navigation.config import NavConfig
from posenet.navigation.estimate import OMEGA, ROT, VEL, Estimate, T, camera_estimate
from posenet.navigation.filter import NavState, Step
from posenet.navigation.noise import NoiseModel, measurement, require_noise
from posenet.navigation.scene import TargetBody, make_filter, sequence_frames, target_body
from posenet.navigation.smoother import smooth
from posenet.navigation.so3 import angle_deg, log
from scgen.io import SequenceFrame, read_sequence_frames

Key = tuple[int, int]  # (scene_id, im_id)
THREE_SIGMA_3DOF = float(chi2.ppf(0.9973, 3))
BLOCKS = (("t", T), ("rot", ROT), ("velocity", VEL), ("omega", OMEGA))


@dataclass(frozen=True)
class FramePose:
    """One frame's estimate: pose (camera from model), and where known its velocity, angular velocity
    (camera axes) and covariance (12x12 over t, rotation, velocity, omega: posenet.navigation.estimate)."""

    R: np.ndarray
    t: np.ndarray
    velocity: np.ndarray | None = None
    omega: np.ndarray | None = None
    cov: np.ndarray | None = None

    @staticmethod
    def of(e: Estimate) -> FramePose:
        return FramePose(e.R, e.t, e.velocity, e.omega, e.cov)


@dataclass
class SequenceRun:
    """A sequence through the filter: its keys in time order, each frame's step, filtered and smoothed
    estimates (None before the start)."""

    keys: list[Key]
    steps: list[Step] = field(default_factory=list)
    filtered: list[Estimate | None] = field(default_factory=list)
    smoothed: list[Estimate | None] = field(default_factory=list)


def run_filter(
    keys: list[Key],
    frames: Mapping[Key, SequenceFrame],
    poses: Mapping[Key, tuple[np.ndarray, np.ndarray, float]],
    obj: ObjectModel,
    body: TargetBody,
    noise: NoiseModel,
    config: NavConfig,
) -> SequenceRun:
    """One sequence's frames (`keys`, in time order) through the filter and the smoother, each frame's
    pose (R, t, confidence) its measurement where it has one."""
    f = make_filter(body, obj.diameter, obj.symmetries, frames[keys[0]], config, noise.bias())
    run = SequenceRun(keys)
    for key in keys:
        frame = frames[key]
        m = measurement(*poses[key], noise) if key in poses else None
        step = f.step(frame.time_s, sequence_frames(frame), m)
        run.steps.append(step)
        run.filtered.append(_estimate(step.posterior, step, body))
    for step, state in zip(run.steps, smooth(f.history), strict=True):
        run.smoothed.append(_estimate(state, step, body))
    return run


def _estimate(state: NavState | None, step: Step, body: TargetBody) -> Estimate | None:
    return None if state is None else camera_estimate(state, step.frames, body.centre_of_mass)


def finite_differences(
    keys: list[Key], poses: Mapping[Key, FramePose], frames: Mapping[Key, SequenceFrame]
) -> dict[Key, FramePose]:
    """Per-frame poses with the velocity and angular velocity of their finite differences: central where
    both neighbours have a pose, else one-sided, none without a posed neighbour."""
    out = {}
    for k, key in enumerate(keys):
        if key not in poses:
            continue
        p = poses[key]
        before = keys[k - 1] if k > 0 and keys[k - 1] in poses else None
        after = keys[k + 1] if k + 1 < len(keys) and keys[k + 1] in poses else None
        a, b = before or key, after or key
        if a == b:
            out[key] = p
            continue
        dt = frames[b].time_s - frames[a].time_s
        pa, pb = poses[a], poses[b]
        velocity = (pb.t - pa.t) / dt
        omega = log(pb.R @ pa.R.T) / dt
        out[key] = FramePose(p.R, p.t, velocity, omega)
    return out


def navigation_figures(
    estimates: Mapping[Key, FramePose],
    sequences: Mapping[int, list[Key]],
    truth: Mapping[Key, tuple[np.ndarray, np.ndarray]],
    frames: Mapping[Key, SequenceFrame],
    obj: ObjectModel,
) -> dict[str, Any]:
    """The figures of `estimates` over every frame of `sequences` (sequence id -> keys in time order)."""
    keys = [k for ks in sequences.values() for k in ks]
    posed = [k for k in keys if k in estimates]
    out: dict[str, Any] = {"frames": len(keys), "posed": len(posed)}
    add_ok = 0
    if posed:
        R_p = torch.from_numpy(np.stack([estimates[k].R for k in posed]))
        t_p = torch.from_numpy(np.stack([estimates[k].t for k in posed]))
        R_g = torch.from_numpy(np.stack([truth[k][0] for k in posed]))
        t_g = torch.from_numpy(np.stack([truth[k][1] for k in posed]))
        points = torch.from_numpy(obj.pm_points)
        add = (adds_error if obj.symmetric else add_error)(R_p, t_p, R_g, t_g, points).numpy()
        add_ok = int(np.sum(add < 0.1 * obj.diameter))
        aligned = {k: nearest_twin(estimates[k].R, *truth[k], obj.symmetries) for k in posed}
        R_a = np.stack([aligned[k][0] for k in posed])
        re = angle_deg(np.swapaxes(R_p.numpy(), 1, 2) @ R_a)
        te = np.linalg.norm(t_p.numpy() - t_g.numpy(), axis=1)
        out |= {"re_deg_median": float(np.median(re)), "te_m_median": float(np.median(te))}
    out["add_0.1d"] = add_ok / len(keys) if keys else math.nan
    out |= _jitter(estimates, sequences)
    out |= _motion(estimates, posed, frames)
    out |= _consistency(estimates, posed, aligned if posed else {}, frames)
    return out


def nearest_twin(
    R: np.ndarray, R_gt: np.ndarray, t_gt: np.ndarray, symmetries: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The symmetric pose of the truth (R_gt S, t_gt + R_gt S_t) closest in rotation to R: what an
    estimate of a symmetric object is scored against (the truth itself without symmetries)."""
    twins = [(R_gt @ S[:3, :3], t_gt + R_gt @ S[:3, 3]) for S in symmetries]
    return min(twins, key=lambda twin: float(np.linalg.norm(log(R @ twin[0].T))))


def _jitter(
    estimates: Mapping[Key, FramePose], sequences: Mapping[int, list[Key]]
) -> dict[str, float | None]:
    """RMS second differences of t (m) and of the rotation (deg) over consecutive posed frames, pooled."""
    sq_t, sq_r = [], []
    for keys in sequences.values():
        for a, b, c in zip(keys, keys[1:], keys[2:], strict=False):
            if a in estimates and b in estimates and c in estimates:
                ea, eb, ec = estimates[a], estimates[b], estimates[c]
                sq_t.append(float(np.sum((ec.t - 2 * eb.t + ea.t) ** 2)))
                D1, D0 = ec.R @ eb.R.T, eb.R @ ea.R.T
                sq_r.append(float(angle_deg(D1 @ D0.T)) ** 2)
    return {"jitter_t_m": float(np.sqrt(np.mean(sq_t))) if sq_t else None,
            "jitter_rot_deg": float(np.sqrt(np.mean(sq_r))) if sq_r else None}  # fmt: skip


def _motion(
    estimates: Mapping[Key, FramePose], posed: list[Key], frames: Mapping[Key, SequenceFrame]
) -> dict[str, float | None]:
    """Median errors of the velocity (m/s) and angular velocity (deg/s) where both are estimated."""
    ev, ew = [], []
    for k in posed:
        e, f = estimates[k], frames[k]
        if e.velocity is not None and f.velocity is not None:
            ev.append(float(np.linalg.norm(e.velocity - np.asarray(f.velocity))))
        if e.omega is not None and f.angular_velocity is not None:
            ew.append(float(np.degrees(np.linalg.norm(e.omega - np.asarray(f.angular_velocity)))))
    return {"velocity_err_median": float(np.median(ev)) if ev else None,
            "omega_err_deg_median": float(np.median(ew)) if ew else None}  # fmt: skip


def _consistency(
    estimates: Mapping[Key, FramePose],
    posed: list[Key],
    truth: Mapping[Key, tuple[np.ndarray, np.ndarray]],
    frames: Mapping[Key, SequenceFrame],
) -> dict[str, float | None]:
    """Per block: the share of frames inside the 3-sigma ellipsoid and the mean NEES."""
    nees: dict[str, list[float]] = {name: [] for name, _ in BLOCKS}
    for k in posed:
        e, f = estimates[k], frames[k]
        if e.cov is None:
            continue
        R_g, t_g = truth[k]
        errors = {"t": t_g - e.t, "rot": log(R_g @ e.R.T)}
        if f.velocity is not None and e.velocity is not None:
            errors["velocity"] = np.asarray(f.velocity) - e.velocity
        if f.angular_velocity is not None and e.omega is not None:
            errors["omega"] = np.asarray(f.angular_velocity) - e.omega
        for name, block in BLOCKS:
            if name in errors:
                C = e.cov[block, block]
                nees[name].append(float(errors[name] @ np.linalg.solve(C, errors[name])))
    out: dict[str, float | None] = {}
    for name, values in nees.items():
        out[f"in_3sigma_{name}"] = float(np.mean(np.array(values) <= THREE_SIGMA_3DOF)) if values else None
        out[f"nees_{name}"] = float(np.mean(values)) if values else None
    return out


def sequence_keys(keys: list[Key], frames: Mapping[Key, SequenceFrame]) -> dict[int, list[Key]]:
    """The keys of each sequence, in time order."""
    out: dict[int, list[Key]] = {}
    for key in sorted(keys, key=lambda k: (frames[k].sequence_id, frames[k].frame)):
        out.setdefault(frames[key].sequence_id, []).append(key)
    return out


def evaluate_navigation(
    records: list[dict[str, Any]],
    truth: Mapping[Key, tuple[np.ndarray, np.ndarray]],
    frames: Mapping[Key, SequenceFrame],
    obj: ObjectModel,
    body: TargetBody,
    noise: NoiseModel,
    config: NavConfig,
) -> dict[str, Any]:
    """Per-frame poses (`records`: scene_id, im_id, R, t, confidence; None R for none), filtered and
    smoothed, scored over every frame of the split (`truth`: each frame's pose): {"per_frame",
    "filtered", "smoothed"} figures (navigation_figures; per-frame motion by finite differences)."""
    poses = {(r["scene_id"], r["im_id"]): (np.reshape(r["R"], (3, 3)), np.asarray(r["t"]), r["confidence"])
             for r in records if r.get("R") is not None}  # fmt: skip
    sequences = sequence_keys(list(truth), frames)
    per_frame: dict[Key, FramePose] = {}
    filtered: dict[Key, FramePose] = {}
    smoothed: dict[Key, FramePose] = {}
    for keys in sequences.values():
        raw = {k: FramePose(poses[k][0], poses[k][1]) for k in keys if k in poses}
        per_frame |= finite_differences(keys, raw, frames)
        run = run_filter(keys, frames, poses, obj, body, noise, config)
        filtered |= {k: FramePose.of(e) for k, e in zip(keys, run.filtered, strict=True) if e is not None}
        smoothed |= {k: FramePose.of(e) for k, e in zip(keys, run.smoothed, strict=True) if e is not None}
    columns = {"per_frame": per_frame, "filtered": filtered, "smoothed": smoothed}
    return {name: navigation_figures(est, sequences, truth, frames, obj) for name, est in columns.items()}


# the navigation table's rows: (label, figure key(s) joined by "|", format; "%": a share in percent)
NAVIGATION_ROWS: tuple[tuple[str, str, str], ...] = (
    ("frames with a pose", "posed", "d"),
    ("ADD@0.1d, every frame (%)", "add_0.1d", "%"),
    ("rotation error, median (deg)", "re_deg_median", ".2f"),
    ("translation error, median (m)", "te_m_median", ".4f"),
    ("translation jitter (m)", "jitter_t_m", ".2e"),
    ("rotation jitter (deg)", "jitter_rot_deg", ".2e"),
    ("velocity error, median (m/s)", "velocity_err_median", ".2e"),
    ("angular velocity error, median (deg/s)", "omega_err_deg_median", ".3f"),
    ("t inside 3 sigma (%)", "in_3sigma_t", "%"),
    ("rotation inside 3 sigma (%)", "in_3sigma_rot", "%"),
    ("velocity inside 3 sigma (%)", "in_3sigma_velocity", "%"),
    ("angular velocity inside 3 sigma (%)", "in_3sigma_omega", "%"),
    ("mean NEES t / rotation (3 if consistent)", "nees_t|nees_rot", ".2f"),
    ("mean NEES velocity / angular velocity", "nees_velocity|nees_omega", ".2f"),
)
NAVIGATION_LEGEND = (
    "per frame: the network's poses, motion by finite differences; filtered: the MEKF over them in time "
    "order; smoothed: the RTS smoother (docs/navigation.md). Jitter: RMS second difference over posed frames."
)


def navigation_table(figures: Mapping[str, Mapping[str, Any]]) -> list[list[str]]:
    """NAVIGATION_ROWS of each column of `figures` (per_frame, filtered, smoothed) as table rows."""

    def cell(fig: Mapping[str, Any], key: str, fmt: str) -> str:
        values = [fig.get(k) for k in key.split("|")]
        if any(v is None or (isinstance(v, float) and math.isnan(v)) for v in values):
            return "-"
        if fmt == "%":
            return " / ".join(f"{100 * v:.1f}" for v in values)
        return " / ".join(format(v, fmt) for v in values)

    return [[label, *(cell(f, key, fmt) for f in figures.values())] for label, key, fmt in NAVIGATION_ROWS]


def navigate_split(
    data: Path, split: str, ckpt: Path, records: list[dict[str, Any]], config: NavConfig
) -> dict[str, Any] | None:
    """`evaluate_navigation` of an eval's records on a sequence split, with the noise calibrated beside
    the checkpoint (posenet calibrate); None for a split of independent frames. The object and its
    surface points are the checkpoint's, as eval's ADD uses them."""
    frames = read_sequence_frames(data)
    if not frames or not records:
        return None
    noise = NoiseModel.load(require_noise(ckpt))
    state = load_checkpoint(ckpt, kind="pose")
    cfg = config_from_dict(state["config"])
    obj_id = records[0]["obj_id"]
    obj = load_object_model(data, obj_id, state["model_config"]["num_regions"], cfg.data.num_pm_points)
    truth = {i.key: (i.R, i.t) for i in scan_split(data, split, obj_id)}
    body = target_body(obj.vertices, obj.faces)
    figures = evaluate_navigation(records, truth, frames, obj, body, noise, config)
    return {**figures, "noise": noise.source, "config": asdict(config)}
