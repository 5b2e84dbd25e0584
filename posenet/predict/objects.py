"""Poses of several objects per image: one detector of several classes, one pose network per object.

GDRNPP's way: the detector (a checkpoint of `posenet train-detector` over every object of a dataset) finds
each object's boxes with its obj_id, and each box goes to the pose network of that object (a checkpoint of
`posenet train --obj-id K`, whose config names its `data.obj_id`), as a given box goes to a `Predictor`.
A box of an object no pose network was given for is skipped, with one warning per object.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch

from posenet.data.camera import Camera, make_camera, map_box, to_training_camera
from posenet.data.dataset import image_tensor
from posenet.data.object_model import ObjectModel
from posenet.detection.options import MIN_SCORE
from posenet.errors import PosenetError
from posenet.predict.options import PREDICT_PASSES, SAME_CROP_IOU
from posenet.predict.pixels import to_bgr8
from posenet.predict.predictor import Pose, Predictor, Timings, _Clock, detector_box

# RGB [0, 1] -> every box kept: ([x0, y0, x1, y1] pixel edges, score, obj_id), best first
LabelledDetector = Callable[[np.ndarray], list[tuple[np.ndarray, float, int]]]


@dataclass(frozen=True)
class ObjectPose:
    """One detected object's answer: its obj_id and its Pose (score: the detector's)."""

    obj_id: int
    pose: Pose


class ObjectsPredictor:
    """Pose networks keyed by obj_id behind one detector of several objects, ready for images from any
    camera. The detector runs in the first network's training camera; each box it keeps (scoring at least
    `min_score`) is posed by its object's Predictor as a given box."""

    def __init__(
        self,
        predictors: dict[int, Predictor],
        detector: LabelledDetector,
        min_score: float = MIN_SCORE,
        warn: Callable[[str], None] | None = None,
    ) -> None:
        self.predictors, self.detector, self.min_score = predictors, detector, min_score
        self.timings = Timings()
        for predictor in predictors.values():  # one latency account for the whole image
            predictor.timings = self.timings
        self.camera = next(iter(predictors.values())).camera  # the detector's camera
        self.warn = warn or (lambda message: warnings.warn(message, stacklevel=4))
        self.skipped: set[int] = set()  # objects detected without a pose network, warned of once

    @classmethod
    def load(
        cls,
        ckpts: Sequence[Path],
        detector: Path,
        device: str | torch.device = "cpu",
        data: Path | None = None,
        min_score: float | None = None,
        passes: int = PREDICT_PASSES,
        same_crop_iou: float = SAME_CROP_IOU,
    ) -> ObjectsPredictor:
        """The pose checkpoints `ckpts` (one per object: two of one object are refused) and the detector
        checkpoint `detector` on `device`; the other arguments as `Predictor.load`'s."""
        dev = torch.device(device)
        predictors: dict[int, Predictor] = {}
        for ckpt in ckpts:
            predictor = Predictor.load(ckpt, None, dev, data, None, min_score, passes, same_crop_iou)
            obj_id = predictor.obj.obj_id
            if obj_id in predictors:
                raise PosenetError(f"two pose checkpoints of object {obj_id}: give one per object ({ckpt})")
            predictors[obj_id] = predictor
        floor = MIN_SCORE if min_score is None else min_score
        return cls(predictors, load_labelled_detector(detector, dev), floor)

    @property
    def obj_ids(self) -> list[int]:
        """The objects this predictor poses, in the order their checkpoints came."""
        return list(self.predictors)

    def objects(self) -> dict[int, ObjectModel]:
        """Each posed object's model, by obj_id."""
        return {k: p.obj for k, p in self.predictors.items()}

    def detect(self, image: np.ndarray, camera: Camera) -> list[tuple[int, tuple[float, ...], float]]:
        """(obj_id, box [x, y, w, h] in the user's image, score) of each box the detector keeps over the
        score floor in `image` (BGR, of `camera`, fitted to it), best first."""
        with _Clock(self.timings, "crop"):
            seen = to_training_camera(image, camera, self.camera)
        with _Clock(self.timings, "detector"):
            found = self.detector(seen[..., ::-1].astype(np.float32) / 255.0)
        out = []
        for edges, score, obj_id in found:
            if score >= self.min_score:
                box, _ = detector_box(edges, score)
                out.append((obj_id, tuple(float(v) for v in map_box(box, self.camera, camera)), score))
        return out

    def __call__(self, image: np.ndarray, camera: Camera | np.ndarray) -> list[ObjectPose]:
        """The pose of every object the detector finds in `image` (what `Predictor.__call__` takes) seen by
        `camera` (a Camera, or a 3x3 K); none found: an empty list."""
        image, _ = to_bgr8(image)
        user = camera if isinstance(camera, Camera) else make_camera(camera)
        user = user.for_image((image.shape[1], image.shape[0]))
        poses = []
        for obj_id, box, score in self.detect(image, user):
            predictor = self.predictors.get(obj_id)
            if predictor is None:
                self._skip(obj_id)
                continue
            poses.append(ObjectPose(obj_id, replace(predictor(image, user, box), score=score)))  # type: ignore[arg-type]
        return poses

    def _skip(self, obj_id: int) -> None:
        if obj_id not in self.skipped:
            self.skipped.add(obj_id)
            self.warn(f"Warning: the detector found object {obj_id}, which no pose checkpoint is for: its "
                      f"boxes are skipped")  # fmt: skip


def load_labelled_detector(path: Path, device: torch.device) -> LabelledDetector:
    """A detector checkpoint's every kept box with its obj_id, in torch (a `.onnx` graph keeps one box)."""
    if Path(path).suffix == ".onnx":
        raise PosenetError(
            f"{path}: several objects need the detector's checkpoint (.pt), not its ONNX graph"
        )
    from posenet.detection.detect import detector_obj_ids, found_boxes, load_detector

    model, state = load_detector(Path(path), device)
    obj_ids = detector_obj_ids(state)

    @torch.inference_mode()
    def boxes(rgb: np.ndarray) -> list[tuple[np.ndarray, float, int]]:
        pred = model([image_tensor(rgb).to(device)])[0]
        return [(np.asarray(f.box, np.float64), f.score, f.obj_id) for f in found_boxes(pred, obj_ids)]

    return boxes
