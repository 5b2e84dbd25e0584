"""Per-sequence figures of an evaluation on a rendezvous-sequence split: the baseline a tracker is measured
against.

For each sequence, in time order: the rotation and translation error of every frame (the error along
time) with their median and maximum, and the frame-to-frame jitter of the estimates beside that of the
ground truth. Jitter is the RMS of the second difference over consecutive frames: of the translation,
|t_{k+1} - 2 t_k + t_{k-1}| (m), and of the rotation, the angle of D_k D_{k-1}ᵀ with D_k = R_{k+1} R_kᵀ
the turn from frame k to k+1 (deg). Both vanish for motion at constant velocity and rate in the camera
frame, so the truth's is the floor the dynamics set and the estimate's excess is noise a filter removes.
A frame without an estimate (target not visible, so not evaluated; missed; PnP failed) leaves the triples
it is in out of the estimate's jitter; the truth's is over every frame of the sequence. Sequence ids and
times come from the dataset's metadata.csv (scgen.io.read_sequence_frames).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from posenet.data.layout import scan_split
from posenet.evaluation.evaluate import EvalResult, format_table
from scgen.io import SequenceFrame, read_sequence_frames

Pose = tuple[np.ndarray, np.ndarray]  # (R (3, 3), t (3,) in metres)


def translation_jitter_m(t: np.ndarray, ok: np.ndarray) -> float | None:
    """RMS of |t_{k+1} - 2 t_k + t_{k-1}| over the triples of consecutive frames all `ok`; None if none."""
    keep = ok[:-2] & ok[1:-1] & ok[2:]
    if not keep.any():
        return None
    second = t[2:] - 2 * t[1:-1] + t[:-2]
    return float(np.sqrt(np.mean(np.sum(second[keep] ** 2, axis=1))))


def rotation_jitter_deg(R: np.ndarray, ok: np.ndarray) -> float | None:
    """RMS of the angle of D_k D_{k-1}ᵀ (D_k = R_{k+1} R_kᵀ) over the triples of consecutive frames all
    `ok`; None if none."""
    keep = ok[:-2] & ok[1:-1] & ok[2:]
    if not keep.any():
        return None
    D = R[1:] @ np.swapaxes(R[:-1], 1, 2)
    change = Rotation.from_matrix((D[1:] @ np.swapaxes(D[:-1], 1, 2))[keep]).magnitude()
    return float(np.degrees(np.sqrt(np.mean(change**2))))


def _error(record: Mapping[str, Any] | None, key: str) -> float | None:
    """A record's error, None without a finite one (no record: the target not visible; or no estimate)."""
    value = None if record is None else record[key]
    return value if value is not None and math.isfinite(value) else None


def sequence_figures(
    records: Sequence[Mapping[str, Any]],
    truth: Mapping[tuple[int, int], Pose],
    frames: Mapping[tuple[int, int], SequenceFrame],
) -> list[dict[str, Any]]:
    """One entry per sequence of the split (`truth`: every image's ground-truth pose, (scene_id, im_id) ->
    (R, t)): its frames, those evaluated (the records': a target not visible is not), those failed (no
    estimate), the median and maximum rotation (deg) and translation (m) error over the estimated frames,
    the jitter of the estimates and of the truth over all its frames, and `series`, the per-frame table
    (errors None where there is no estimate)."""
    by_key = {(r["scene_id"], r["im_id"]): r for r in records}
    by_sequence: dict[int, dict[int, tuple[int, int]]] = {}
    for key in truth:
        by_sequence.setdefault(frames[key].sequence_id, {})[frames[key].frame] = key
    out = []
    for seq, keys in sorted(by_sequence.items()):
        n = max(keys) + 1  # arrays over frame 0..n-1: a frame absent from the split is in no triple
        est_R, gt_R = np.tile(np.eye(3), (n, 1, 1)), np.tile(np.eye(3), (n, 1, 1))
        est_t, gt_t = np.zeros((n, 3)), np.zeros((n, 3))
        est_ok, gt_ok = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
        for k, key in keys.items():
            gt_R[k], gt_t[k] = truth[key]
            gt_ok[k] = True
            r = by_key.get(key)
            if r is not None and r["R"] is not None:
                est_R[k], est_t[k] = np.reshape(r["R"], (3, 3)), r["t"]
                est_ok[k] = True
        evaluated = [by_key[key] for key in keys.values() if key in by_key]
        re = [e for r in evaluated if (e := _error(r, "re_deg")) is not None]
        te = [e for r in evaluated if (e := _error(r, "te_m")) is not None]
        out.append({
            "sequence_id": seq,
            "frames": len(keys),
            "evaluated": len(evaluated),
            "failed": len(evaluated) - int(est_ok.sum()),
            "re_deg_median": float(np.median(re)) if re else None,
            "re_deg_max": max(re) if re else None,
            "te_m_median": float(np.median(te)) if te else None,
            "te_m_max": max(te) if te else None,
            "jitter_t_m": translation_jitter_m(est_t, est_ok),
            "jitter_t_m_truth": translation_jitter_m(gt_t, gt_ok),
            "jitter_rot_deg": rotation_jitter_deg(est_R, est_ok),
            "jitter_rot_deg_truth": rotation_jitter_deg(gt_R, gt_ok),
            "series": [
                {"frame": k, "time_s": frames[key].time_s, "re_deg": _error(by_key.get(key), "re_deg"),
                 "te_m": _error(by_key.get(key), "te_m")}
                for k, key in sorted(keys.items())
            ],
        })  # fmt: skip
    return out


# The per-sequence table's columns: (header, key, format)
SEQUENCE_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("frames", "frames", "d"),
    ("evaluated", "evaluated", "d"),
    ("failed", "failed", "d"),
    ("re median (deg)", "re_deg_median", ".2f"),
    ("re max (deg)", "re_deg_max", ".2f"),
    ("te median (m)", "te_m_median", ".4f"),
    ("te max (m)", "te_m_max", ".4f"),
    ("t jitter (m)", "jitter_t_m", ".2e"),
    ("t jitter truth (m)", "jitter_t_m_truth", ".2e"),
    ("rot jitter (deg)", "jitter_rot_deg", ".2e"),
    ("rot jitter truth (deg)", "jitter_rot_deg_truth", ".2e"),
)
SEQUENCE_LEGEND = (
    "re, te: error over the frames with an estimate; jitter: RMS second difference over consecutive "
    "frames (docs/posenet.md)"
)


def sequence_table(figures: Sequence[Mapping[str, Any]], title: str) -> str:
    """`sequence_figures` as a table, one row per sequence, and its legend; a figure that cannot be had
    prints as "-"."""

    def cell(value: Any, fmt: str) -> str:
        return "-" if value is None else format(value, fmt)

    rows = [[str(f["sequence_id"]), *(cell(f[k], fmt) for _, k, fmt in SEQUENCE_COLUMNS)] for f in figures]
    return format_table([title, *(h for h, _, _ in SEQUENCE_COLUMNS)], rows) + "\n" + SEQUENCE_LEGEND


def per_sequence(
    data: Path, split: str, results: Mapping[str, EvalResult]
) -> dict[str, list[dict[str, Any]]]:
    """`sequence_figures` of each PnP method's result on a split of a sequence dataset; empty for a dataset
    of independent frames."""
    frames = read_sequence_frames(data)
    first = next(iter(results.values())).records
    if not frames or not first:
        return {}
    truth = {i.key: (i.R, i.t) for i in scan_split(data, split, first[0]["obj_id"])}
    return {m: sequence_figures(r.records, truth, frames) for m, r in results.items()}
