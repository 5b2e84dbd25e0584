"""Tracking along a video or a sequence on the navigation filter: each frame's crop seeded from the
filter's prediction of the pose at that frame's time, the network's pose the filter's measurement.

Per frame, at time t (the sequence's, or the frame's index over the video's rate):

1. The filter (posenet.navigation) predicts the state at t. While it is locked (started, its predicted
   position within LOST_SIGMA diameters at 3 sigma, the predicted model box in view), the crop is the
   model's box at the predicted pose: what a re-crop would take, before the network has run.
2. Otherwise the previous frame's own pose seeds it, where that pose is good (confident, in view): a
   track the filter has not started on yet, or lost.
3. Otherwise the detector runs: to start, and to find the target again. While it finds nothing (an
   eclipse, the target out of view) it runs on every SEARCH_EVERY-th frame only; a frame between
   searches has no pose (box_source "none").

The pose (the raw measurement, kept) goes into the filter with its calibrated covariance; the filter gates
it, updates or coasts. Through an eclipse the filter coasts on its prediction and its covariance grows;
the detector is not needed while the prediction holds. At the end of a sequence the smoother gives the
best trajectory of the frames seen (`smoothed`). Without `seed_crops` (posenet predict --filter) every
frame is boxed as without the filter, and the filter only takes the poses.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from posenet.data.camera import Camera, make_camera
from posenet.navigation.config import NavConfig
from posenet.navigation.estimate import OMEGA, ROT, VEL, Estimate, T, camera_estimate
from posenet.navigation.filter import CAMERA, POS, CameraFrames, NavState, PoseFilter, Step
from posenet.navigation.noise import NoiseModel, measurement, require_noise
from posenet.navigation.scene import make_filter, target_body
from posenet.navigation.smoother import smooth
from posenet.predict.options import LOW_CONFIDENCE
from posenet.predict.predictor import Box, Pose, Predictor
from posenet.predict.recrop import in_view, model_box
from scgen.io import SequenceFrame

MIN_IN_VIEW = 0.5  # a seed box with less of its area in the image has left the view
LOST_FLAGS = ("no_detection", "behind_camera", "outside_view")
LOST_SIGMA = 0.5  # the filter is lost once its predicted position's 3 sigma exceeds this many diameters
SEARCH_EVERY = 5  # while the detector finds nothing, it runs on every this-many-th frame
TRACK, POSE, DETECTOR, GIVEN, NONE = "track", "pose", "detector", "given", "none"  # where a crop came from


@dataclass(frozen=True)
class TrackedFrame:
    """One frame of a track: the network's pose (the raw measurement; NO_DETECTION-like without one),
    where its crop came from, the filter's step and its estimate at the frame's time (None before the
    start)."""

    pose: Pose | None
    source: str
    step: Step
    estimate: Estimate | None

    def to_json(self) -> dict[str, Any]:
        """The filter's answer for predictions.jsonl (`filter`): None before the start."""
        if self.estimate is None:
            return {"filter": None}
        return {"filter": {**estimate_json(self.estimate), "coasting": self.step.coasting,
                           "rejected": self.step.rejected, "twin": self.step.twin,
                           "nis": [_round(self.step.nis_rot), _round(self.step.nis_t)]}}  # fmt: skip


def estimate_json(e: Estimate) -> dict[str, Any]:
    """An estimate as JSON: pose, velocity (m/s) and angular velocity (rad/s) in camera axes, and their
    1-sigma per axis (rotation and angular velocity in degrees)."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(e.R).as_quat(canonical=True)
    return {
        "R": e.R.ravel().tolist(),
        "t": e.t.tolist(),
        "quaternion": [w, x, y, z],
        "velocity": e.velocity.tolist(),
        "omega": e.omega.tolist(),
        "sigma": {
            "t": e.sigma(T).tolist(),
            "rot_deg": np.degrees(e.sigma(ROT)).tolist(),
            "velocity": e.sigma(VEL).tolist(),
            "omega_deg": np.degrees(e.sigma(OMEGA)).tolist(),
        },  # fmt: skip
    }


def _round(x: float | None) -> float | None:
    return None if x is None else round(float(x), 4)


class Tracker:
    """A Predictor run frame after frame on the navigation filter; `reset(first)` between sequences.
    `noise` is the checkpoint's calibrated measurement noise (posenet calibrate); `detections` counts the
    detector's runs. Without `seed_crops` every frame is boxed as without the filter (the detector on
    every frame, or the given box) and the filter only takes the poses: the crops stay independent of
    the filter's own estimate (posenet predict --filter)."""

    def __init__(
        self,
        predictor: Predictor,
        noise: NoiseModel,
        config: NavConfig | None = None,
        min_confidence: float = LOW_CONFIDENCE,
        search_every: int = SEARCH_EVERY,
        seed_crops: bool = True,
    ) -> None:
        self.predictor, self.noise, self.config = predictor, noise, config or NavConfig()
        self.min_confidence, self.search_every, self.seed_crops = min_confidence, search_every, seed_crops
        self.body = target_body(predictor.obj.vertices, predictor.obj.faces)
        self.detections = 0
        self.reset()

    @classmethod
    def load(cls, ckpt: Path, config: NavConfig | None = None, **predictor: Any) -> Tracker:
        """A tracker for checkpoint `ckpt` (Predictor.load's keywords: detector, device, onnx, passes...)
        with the noise calibrated beside it (posenet.navigation.noise.noise_path)."""
        return cls(Predictor.load(ckpt, **predictor), NoiseModel.load(require_noise(ckpt)), config)

    def reset(self, first: SequenceFrame | None = None) -> None:
        """Forget the track: a new sequence (its first frame tells the filter the chaser's state, if
        the dataset has it)."""
        obj = self.predictor.obj
        bias = self.noise.bias()
        self.filter: PoseFilter = make_filter(
            self.body, obj.diameter, obj.symmetries, first, self.config, bias
        )
        self._previous: Pose | None = None
        self._since_search = self.search_every  # frames since the detector last found nothing

    def __call__(
        self,
        image: np.ndarray,
        camera: Camera | np.ndarray,
        time: float,
        frames: CameraFrames = CAMERA,
        box: Box | None = None,
    ) -> TrackedFrame:
        """The frame at `time` (s): its pose (at `box` if given), the filter's step and estimate."""
        cam = (camera if isinstance(camera, Camera) else make_camera(camera)).for_image(image.shape[1::-1])
        pose, source = None, NONE
        self._predicted: tuple[NavState, np.ndarray] | None = None
        if box is not None:
            pose, source = self.predictor(image, cam, box), GIVEN
        elif not self.seed_crops:
            pose, source = self.predictor(image, cam), DETECTOR
            self.detections += 1
        else:
            seed, source = self.seed(time, frames, cam)
            if seed is not None:
                pose = self.predictor(image, cam, seed)
            elif self._since_search >= self.search_every:
                pose, source = self.predictor(image, cam), DETECTOR
                self.detections += 1
        found = pose is not None and pose.R is not None
        if source == DETECTOR:
            self._since_search = self.search_every if found else 0
        else:
            self._since_search += 1
        m = measurement(pose.R, pose.t, pose.confidence, self.noise) if found else None  # type: ignore[union-attr]
        step = self.filter.step(time, frames, m, self._predicted)
        self._previous = pose if self.holds(pose) else None
        return TrackedFrame(pose, source, step, self._estimate(step.posterior, frames))

    def _estimate(self, state: NavState | None, frames: CameraFrames) -> Estimate | None:
        return None if state is None else camera_estimate(state, frames, self.body.centre_of_mass)

    def seed(self, time: float, frames: CameraFrames, cam: Camera) -> tuple[Box | None, str]:
        """The crop box of the frame at `time`: the filter's predicted pose while it is locked, else the
        previous frame's good pose; None (detect) without either."""
        size = cam.size or (0, 0)
        predicted = self._predicted = self.filter.predict(time, frames)  # the step takes it, not made twice
        if predicted is not None:
            state = predicted[0]
            spread = 3.0 * float(np.sqrt(np.linalg.eigvalsh(state.P[POS, POS]).max()))
            if spread <= LOST_SIGMA * self.predictor.obj.diameter:
                R, t = self.filter.expected(state, frames)
                box = self._box(R, t, cam, size)
                if box is not None:
                    return box, TRACK
        if self._previous is not None:
            box = self._box(self._previous.R, self._previous.t, cam, size)
            if box is not None:
                return box, POSE
        return None, NONE

    def _box(self, R: Any, t: Any, cam: Camera, size: tuple[int, int]) -> Box | None:
        if t is None or R is None or t[2] <= 0:
            return None
        box = model_box(self.predictor.obj, R, t, cam)
        return box if box is not None and in_view(box, size, MIN_IN_VIEW) else None

    def holds(self, pose: Pose | None) -> bool:
        """Whether a pose is good enough to seed the next frame: posed, in view, confident."""
        if pose is None or pose.R is None:
            return False
        return not any(f in LOST_FLAGS for f in pose.flags) and pose.confidence >= self.min_confidence

    def smoothed(self) -> list[Estimate | None]:
        """The fixed-interval smoother's estimate of each frame since the last reset (None before the
        filter started): the best trajectory of a recorded sequence."""
        history = self.filter.history
        return [self._estimate(s, step.frames) for s, step in zip(smooth(history), history, strict=True)]
