"""Measurements made from scgen's own trajectories, where the truth is exact: a sequence's track
(scgen.scenes.motion.sequence) and poses drawn around it with a known Gaussian noise, plus injected
outliers and gaps. The tests of posenet.navigation run on these, without a network."""

from __future__ import annotations

import copy
from dataclasses import dataclass
from functools import cache

import numpy as np

from posenet.navigation.estimate import state_from_camera
from posenet.navigation.filter import CAMERA, CameraFrames, Measurement, NavState
from posenet.navigation.so3 import exp
from scgen.scenes.model import load_target
from scgen.scenes.motion.orbit import Orbit
from scgen.scenes.motion.sequence import DEFAULT_SEQUENCE, Track, draw_sequence, sequence_track
from scgen.scenes.motion.tumble import MassProperties, mass_properties

DIAMETER = 0.2  # the bundled model's (scgen's default scale)
SPACECRAFT_M = 20.0  # the real target's diameter: 46 m of range puts the 0.2 m model at 0.46 m
DT = 2.0  # s between frames: a navigation camera's rate
# the injected noise, camera axes: rotation (rad) and translation per unit depth; a pose network's shape
# (the roll about the optical axis and the lateral position are seen best, the depth worst)
SIGMA_ROT = np.radians([3.0, 3.0, 1.5])
SIGMA_T_REL = np.array([0.004, 0.004, 0.03])


@cache
def body() -> MassProperties:
    """The bundled spacecraft's mass properties, as scgen's sequences use them."""
    return mass_properties([mesh for _, mesh in load_target().parts])


@dataclass(frozen=True)
class Scenario:
    """A track and what the filter is told of the chaser at each frame (`frames`), its orbit's mean
    motion (None: the camera-frame models) and the target's inertia (None: constant rate)."""

    track: Track
    frames: list[CameraFrames]
    mean_motion: float | None
    inertia: np.ndarray | None


def scenario(profile: str, attitude: str, seed: int = 3, frames: int = 60, orbit: bool = False,
             pointing: str = "target", rate_deg: tuple[float, float] = (1.0, 2.0)) -> Scenario:  # fmt: skip
    """Sequence 0 of `seed` with one profile and one attitude mode, `frames` frames DT apart. With
    `orbit`, the filter knows the chaser's state (LVLH, inertial, thrust; as posenet reads a dataset's
    metadata.csv, posenet.navigation.scene), else it works in the camera frame."""
    seq = copy.deepcopy(DEFAULT_SEQUENCE)
    seq.update(profile_probs={profile: 1.0}, attitude_probs={attitude: 1.0}, rate_deg=list(rate_deg),
               spacecraft_diameter_m=SPACECRAFT_M)  # fmt: skip
    if profile == "corridor_approach":
        seq["profiles"] = {profile: {"start_m": [46.0, 48.0], "closing_mps": [0.03, 0.06]}}
    props = body()
    draw = draw_sequence(seed, 0, seq, props)
    times = np.arange(frames) * DT
    track = sequence_track(draw, times, DIAMETER / SPACECRAFT_M, props, pointing)
    if not orbit:
        return Scenario(track, [CAMERA] * frames, None, None)
    from posenet.navigation.scene import sequence_frames
    from scgen.io import SequenceFrame
    from scgen.scenes.geometry import matrix_to_quat

    n = Orbit(draw.altitude_m).n
    out = []
    for k in range(frames):
        chaser = {"camera_attitude": tuple(matrix_to_quat(track.R_lc[k])),
                  "camera_rate": tuple(track.camera_rate[k]), "thrust": tuple(track.thrust[k])}  # fmt: skip
        frame = SequenceFrame(0, k, float(times[k]), altitude_km=draw.altitude_m / 1e3, **chaser)
        out.append(sequence_frames(frame))
    return Scenario(track, out, n, props.inertia)


def measure(track: Track, k: int, rng: np.random.Generator, scale: float = 1.0) -> Measurement:
    """Frame k's pose with the injected noise (times `scale`) and the covariance it was drawn from."""
    z = track.t[k][2]
    cov_rot = np.diag((scale * SIGMA_ROT) ** 2)
    cov_t = np.diag((scale * SIGMA_T_REL * z) ** 2)
    R = exp(rng.normal(0.0, scale * SIGMA_ROT)) @ track.R[k]
    t = track.t[k] + rng.normal(0.0, scale * SIGMA_T_REL * z)
    return Measurement(R, t, cov_rot, cov_t)


def state_error(state: NavState, track: Track, k: int, frames: CameraFrames, c: np.ndarray) -> np.ndarray:
    """The true state minus the estimate, in the filter's error state (12,), at frame k: the truth taken
    into the filter's frames (posenet.navigation.estimate.state_from_camera)."""
    true = state_from_camera(
        state.time, track.R[k], track.t[k], track.velocity[k], track.omega[k], frames, c, state.P
    )
    return true.minus(state)
