"""Tracking along a video or a sequence: each frame's crop seeded from the previous frame's pose.

A rendezvous sequence's next crop is already known: the model's box (`bbox_obj`, posenet.predict.recrop)
at the last pose. The detector, the slowest and least accurate stage, runs only to start a track and to
find the target again: when the seeded pose's confidence drops under `min_confidence`, or the seed box
leaves the view (less than `min_in_view` of it inside the image), or the pose lands behind the camera
or outside the view.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from posenet.data.camera import Camera, make_camera
from posenet.predict.predictor import LOW_CONFIDENCE, Box, Pose, Predictor
from posenet.predict.recrop import in_view, projected_box

MIN_IN_VIEW = 0.5  # a seed box with less of its area in the image has left the view: detect again
LOST_FLAGS = ("no_detection", "behind_camera", "outside_view")
TRACK, DETECTOR, GIVEN = "track", "detector", "given"  # where a frame's first box came from


@dataclass
class Tracker:
    """A Predictor run frame after frame, each crop seeded by the last pose; `reset()` between
    sequences. `detections` counts the detector's runs."""

    predictor: Predictor
    min_confidence: float = LOW_CONFIDENCE
    min_in_view: float = MIN_IN_VIEW
    previous: Pose | None = None
    detections: int = 0

    def reset(self) -> None:
        self.previous = None

    def __call__(
        self, image: np.ndarray, camera: Camera | np.ndarray, box: Box | None = None
    ) -> tuple[Pose, str]:
        """The frame's pose (as Predictor's) and where its first box came from (TRACK, DETECTOR, or GIVEN
        for `box`); a given box also seeds the next frame."""
        size = (image.shape[1], image.shape[0])
        if box is not None:
            pose, source = self.predictor(image, camera, box), GIVEN
        else:
            seed = self.seed(camera, size)
            pose = self.predictor(image, camera, seed) if seed is not None else None
            source = TRACK
            if pose is None or not self.holds(pose):
                pose, source = self.predictor(image, camera), DETECTOR
                self.detections += 1
        self.previous = pose if self.holds(pose) else None
        return pose, source

    def seed(self, camera: Camera | np.ndarray, size: tuple[int, int]) -> Box | None:
        """The model's box at the last pose in this frame's camera, None without a pose to follow or when
        that box has left the view."""
        if self.previous is None or self.previous.R is None or self.previous.t is None:
            return None
        cam = (camera if isinstance(camera, Camera) else make_camera(camera)).for_image(size)
        box = projected_box(self.predictor.obj.vertices, self.previous.R, self.previous.t, cam)
        return box if box is not None and in_view(box, size, self.min_in_view) else None

    def holds(self, pose: Pose) -> bool:
        """Whether a pose is good enough to seed the next frame."""
        lost = any(f in LOST_FLAGS for f in pose.flags)
        return pose.R is not None and not lost and pose.confidence >= self.min_confidence
