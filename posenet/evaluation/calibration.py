"""`posenet calibrate`: the measurement noise of a pose network, measured on a labelled split, for the
navigation filter (posenet.navigation.noise).

The network runs on the split as `posenet eval` runs it (ground-truth boxes, or a box file), at predict's
passes (each re-cropped around the model's box at the pose before, as predict and its tracker do), and
each pose's error against the truth is kept with its confidence. A split the network never trained on is
the honest one: `val` by default (the test split stays for the claims).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from posenet.data.layout import scan_split
from posenet.data.object_model import load_object_model
from posenet.errors import PosenetError
from posenet.evaluation.evaluate import evaluate
from posenet.evaluation.navigation import nearest_twin
from posenet.navigation.noise import NoiseModel, calibrate
from posenet.navigation.so3 import log
from posenet.predict.recrop import PREDICT_PASSES

CALIBRATION_SPLIT = "val"


def calibrate_noise(
    data: Path,
    ckpt: Path,
    split: str = CALIBRATION_SPLIT,
    boxes: Path | None = None,
    passes: int = PREDICT_PASSES,
    workers: int = 2,
) -> NoiseModel:
    """The noise model of checkpoint `ckpt` measured on `split` of `data`: every posed image's
    confidence, its rotation error (rotation vector of R_pred R_true^T, camera axes; for an object with
    symmetries, against the symmetric twin of the truth closest to the prediction) and translation
    error, per unit of true depth."""
    result = evaluate(data, ckpt, split, boxes, workers=workers, passes=passes)
    posed = [r for r in result.records if r["R"] is not None and r.get("confidence") is not None]
    if not posed:
        raise PosenetError(f"split '{split}' of {data} gave no pose to calibrate on")
    obj_id = posed[0]["obj_id"]
    truth = {i.key: i for i in scan_split(data, split, obj_id)}
    symmetries = load_object_model(data, obj_id, 1, 1).symmetries
    conf, rot, trans, depth = [], [], [], []
    for r in posed:
        inst = truth[(r["scene_id"], r["im_id"])]
        R_p, t_p = np.reshape(r["R"], (3, 3)), np.asarray(r["t"], np.float64)
        R_t, t_t = nearest_twin(R_p, inst.R, inst.t, symmetries)
        conf.append(r["confidence"])
        rot.append(log(R_p @ R_t.T))
        trans.append(t_p - t_t)
        depth.append(t_t[2])
    source = {"data": str(data), "split": split, "boxes": str(boxes) if boxes else "ground truth",
              "passes": passes, "checkpoint": Path(ckpt).name}  # fmt: skip
    return calibrate(np.array(conf), np.array(rot), np.array(trans), np.array(depth), source)
