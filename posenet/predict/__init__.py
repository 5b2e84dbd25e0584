"""Poses from the images a user brings (`posenet predict`): any camera, a detector or given boxes, the
training crop, JSON lines, BOP / SPEED+ files and overlays. The Python API is `Predictor` and `Pose`."""

from posenet.data.camera import Camera, make_camera
from posenet.predict.predictor import Pose, Predictor

__all__ = ["Camera", "Pose", "Predictor", "make_camera"]
