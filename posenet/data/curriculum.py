"""An attitude curriculum: training starts inside a corridor about the dataset's nominal attitude and
widens to every attitude of the train split.

Where a sample sits in attitude is the tilt of its line of sight: the angle, in the target's own frame,
between the direction towards the camera and the nominal attitude's (scgen's `pose_cone_deg`, here
from R and t alone, so any scgen dataset has it). The corridor widens linearly in solid angle, so the
share of a uniformly drawn line of sight it holds grows linearly from the start cone's to 1.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from posenet.errors import PosenetError
from scgen.dataset.layout import Layout
from scgen.scenes.attitude import nominal_rotation

TOWARDS_CAMERA = np.array([0.0, 0.0, -1.0])  # from a target on the optical axis to the camera


def line_of_sight_tilt_deg(R: np.ndarray, t: np.ndarray, R_nominal: np.ndarray) -> np.ndarray:
    """Per pose (R (N,3,3) model -> camera, t (N,3)): the angle in degrees between the model-frame
    direction towards the camera and the nominal allocentric attitude's."""
    towards = -t / np.linalg.norm(t, axis=1, keepdims=True)
    seen = np.einsum("nji,nj->ni", R, towards)  # R^T (-t / |t|)
    nominal = R_nominal.T @ TOWARDS_CAMERA
    return np.rad2deg(np.arccos(np.clip(seen @ nominal, -1.0, 1.0)))


def cone_cap_deg(start_deg: float, progress: float) -> float:
    """The corridor's half-angle at `progress` (0..1) of its widening: its cap's share of the sphere,
    (1 - cos a) / 2, goes linearly from the start cone's to 1 (every attitude)."""
    share0 = (1.0 - math.cos(math.radians(start_deg))) / 2.0
    share = share0 + (1.0 - share0) * min(max(progress, 0.0), 1.0)
    return math.degrees(math.acos(1.0 - 2.0 * share))


def read_nominal_rotation(root: Path) -> np.ndarray:
    """The nominal allocentric attitude of the scgen dataset at `root` (its config.json's pose table)."""
    path = Layout(root).config_path
    if not path.is_file():
        raise PosenetError(f"{path} is missing: an attitude curriculum needs an scgen dataset's pose.nominal")
    return nominal_rotation(json.loads(path.read_text())["pose"])
