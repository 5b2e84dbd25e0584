"""`posenet calibrate`: the measurement noise of a pose network, measured on labelled images, for the
navigation filter (posenet.navigation.noise).

The network runs as `posenet eval` runs it (ground-truth boxes, or a box file), at predict's passes (each
re-cropped around the model's box at the pose before, as predict and its tracker do), and each pose's
error against the truth is kept with its confidence. Two questions, two kinds of labelled images:

- how large the errors are, per band of confidence: independent views spread over the network's domain
  (a split of a render like its training set's, never trained on: `val` by default; the test split stays
  for the claims);
- how much of an error persists from frame to frame along a sequence, and for how long: labelled
  sequences of the kind the filter will run on (a scgen sequence render, not the one the claims are made
  on; `--sequences`). Without them, a sequence dataset given as the split answers both; a split of
  independent frames answers only the first, and the filter then takes the errors for white.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from posenet.data.layout import scan_split
from posenet.data.object_model import load_object_model
from posenet.errors import PosenetError
from posenet.evaluation.evaluate import evaluate
from posenet.evaluation.navigation import nearest_twin
from posenet.evaluation.options import CALIBRATION_SPLIT
from posenet.navigation.noise import Errors, NoiseModel, calibrate, with_persistence
from posenet.navigation.so3 import log
from posenet.predict.options import LOW_CONFIDENCE, PREDICT_PASSES, SAME_CROP_IOU
from scgen.io import SequenceFrame, read_sequence_frames

Key = tuple[int, int]


def calibrate_noise(
    data: Path,
    ckpt: Path,
    split: str = CALIBRATION_SPLIT,
    boxes: Path | None = None,
    passes: int = PREDICT_PASSES,
    workers: int = 2,
    min_confidence: float = LOW_CONFIDENCE,
    sequences: tuple[Path, str] | None = None,
    same_crop_iou: float = SAME_CROP_IOU,
) -> NoiseModel:
    """The noise model of checkpoint `ckpt`: its error bands from `split` of `data`, and what persists
    along the sequences of `sequences` (a dataset and its split; default: `data` itself where it is a
    sequence dataset). Only poses with a confidence of at least `min_confidence` count: a pose under it
    is no measurement to the filter. `passes` and `same_crop_iou`: predict's, whose poses the filter takes."""
    keys, errors = split_errors(data, ckpt, split, boxes, passes, same_crop_iou, workers, min_confidence)
    source = {"data": str(data), "split": split, "boxes": str(boxes) if boxes else "ground truth",
              "passes": passes, "same_crop_iou": same_crop_iou, "checkpoint": Path(ckpt).name}  # fmt: skip
    model = calibrate(errors, source, min_confidence)
    seq_data, seq_split = sequences if sequences is not None else (data, split)
    frames = read_sequence_frames(seq_data)
    if not frames:
        if sequences is not None:
            raise PosenetError(f"{seq_data} is not a sequence dataset (its metadata.csv has no sequence_id)")
        return model
    if sequences is not None:
        keys, errors = split_errors(
            seq_data, ckpt, seq_split, None, passes, same_crop_iou, workers, min_confidence
        )
    series = sequence_series(keys, frames)
    return with_persistence(model, errors, series, {"data": str(seq_data), "split": seq_split})


def split_errors(
    data: Path, ckpt: Path, split: str, boxes: Path | None, passes: int, same_crop_iou: float, workers: int,
    min_confidence: float,
) -> tuple[list[Key], Errors]:  # fmt: skip
    """The network's errors on a split, one per image posed with at least `min_confidence`: its key, its
    confidence, its rotation error (rotation vector of R_pred R_true^T, camera axes; for an object with
    symmetries, against the symmetric twin of the truth closest to the prediction) and its translation
    error per unit of true depth."""
    result = evaluate(data, ckpt, split, boxes, workers=workers, passes=passes, same_crop_iou=same_crop_iou)
    posed = [r for r in result.records if r["R"] is not None and r.get("confidence", -1.0) >= min_confidence]
    if not posed:
        raise PosenetError(f"split '{split}' of {data} gave no pose with confidence >= {min_confidence} to "
                           f"calibrate on")  # fmt: skip
    obj_id = posed[0]["obj_id"]
    truth = {i.key: i for i in scan_split(data, split, obj_id)}
    symmetries = load_object_model(data, obj_id, 1, 1).symmetries
    keys, conf, rot, rel = [], [], [], []
    for r in posed:
        inst = truth[(r["scene_id"], r["im_id"])]
        R_p, t_p = np.reshape(r["R"], (3, 3)), np.asarray(r["t"], np.float64)
        R_t, t_t = nearest_twin(R_p, inst.R, inst.t, symmetries)
        keys.append(inst.key)
        conf.append(r["confidence"])
        rot.append(log(R_p @ R_t.T))
        rel.append((t_p - t_t) / t_t[2])
    return keys, Errors(np.array(conf), np.array(rot), np.array(rel))


def sequence_series(keys: list[Key], frames: dict[Key, SequenceFrame]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each sequence's (indices into `keys`, times) in time order, of the keys that are sequence frames."""
    by_sequence: dict[int, list[tuple[int, int]]] = {}
    for i, key in enumerate(keys):
        if key in frames:
            by_sequence.setdefault(frames[key].sequence_id, []).append((frames[key].frame, i))
    out = []
    for members in by_sequence.values():
        members.sort()
        index = np.array([i for _, i in members])
        out.append((index, np.array([frames[keys[i]].time_s for i in index])))
    return out
