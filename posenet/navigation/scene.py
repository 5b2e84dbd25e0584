"""What the filter knows of a scene besides the images: the target's body (centre of mass and inertia,
from its mesh) and, along a scgen sequence, the chaser's own state at each frame (its orbit, its
camera's attitude and rate, its thrust: scgen.io.SequenceFrame).

With the chaser's state the filter runs in LVLH and inertial frames, HCW at the orbit's mean motion and
torque-free attitude (`CameraFrames`: N = LVLH, A = I); without it (a user's video, a dataset written
before those columns), in the camera frame at constant velocity and rate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from posenet.navigation.config import NavConfig
from posenet.navigation.filter import CAMERA, CameraFrames, MeasurementBias, PoseFilter
from scgen.io import ScgenError, SequenceFrame
from scgen.scenes.motion.orbit import R_EARTH, lvlh_to_inertial, mean_motion
from scgen.scenes.motion.tumble import mass_properties, quats_to_matrices


@dataclass(frozen=True)
class TargetBody:
    """The target's centre of mass (model frame, m) and inertia tensor per unit mass (None: unknown), and
    where they came from."""

    centre_of_mass: np.ndarray
    inertia: np.ndarray | None
    source: str


def target_body(vertices: np.ndarray, faces: np.ndarray) -> TargetBody:
    """The mass properties of a uniform solid of the mesh (scgen.scenes.motion.tumble.mass_properties,
    the ones scgen's tumbles use); a mesh enclosing no volume has its bounding box's centre and no
    inertia (the filter then holds the rate constant)."""
    try:
        props = mass_properties(trimesh.Trimesh(np.asarray(vertices), np.asarray(faces), process=False))
    except ScgenError as exc:
        centre = 0.5 * (np.min(vertices, axis=0) + np.max(vertices, axis=0))
        return TargetBody(np.asarray(centre, np.float64), None, f"bounding-box centre ({exc})")
    return TargetBody(props.centre_of_mass, props.inertia, props.source)


def orbit_rate(frame: SequenceFrame) -> float | None:
    """The mean motion (rad/s) of a frame's circular orbit, None where the frame does not give its camera's
    attitude (without it the LVLH frame cannot be used)."""
    if frame.altitude_km is None or frame.camera_attitude is None:
        return None
    return mean_motion(R_EARTH + 1e3 * frame.altitude_km)


def sequence_frames(frame: SequenceFrame | None) -> CameraFrames:
    """The filter's frames at a sequence frame: N = LVLH (camera -> LVLH from the chaser's camera
    attitude), A = inertial (LVLH turned by n t), the camera's rates relative to both, and the target's
    acceleration relative to the chaser (its thrust, negated). CAMERA where the frame gives none."""
    n = None if frame is None else orbit_rate(frame)
    if n is None or frame is None or frame.camera_attitude is None:
        return CAMERA
    R_lc = quats_to_matrices(np.asarray(frame.camera_attitude))
    R_ic = lvlh_to_inertial(n, frame.time_s) @ R_lc
    w_cn = np.asarray(frame.camera_rate if frame.camera_rate is not None else (0.0, 0.0, 0.0))
    w_ca = w_cn + R_lc.T @ np.array([0.0, 0.0, n])  # LVLH turns in I at n about its z
    accel = -np.asarray(frame.thrust if frame.thrust is not None else (0.0, 0.0, 0.0))
    return CameraFrames(R_lc, R_ic, w_cn, w_ca, accel)


def make_filter(
    body: TargetBody,
    diameter: float,
    symmetries: np.ndarray | None,
    first: SequenceFrame | None,
    config: NavConfig | None = None,
    bias: MeasurementBias | None = None,
) -> PoseFilter:
    """A filter for a target: in LVLH with HCW and torque-free attitude where the sequence's first frame
    gives the chaser's state (orbit_rate), else in the camera frame at constant velocity and rate; with
    the measurements' persistent `bias` (posenet.navigation.noise.NoiseModel.bias)."""
    n = None if first is None else orbit_rate(first)
    inertia = body.inertia if n is not None else None
    return PoseFilter.for_motion(body.centre_of_mass, diameter, symmetries, n, inertia, config, bias)
