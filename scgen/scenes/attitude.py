"""The target's attitude: uniform over SO(3), or a rendezvous corridor (a cone about a nominal attitude).

A chaser approaching a known, attitude-held target does not see it tumble at random: its line of sight
stays inside an approach corridor about the target's docking or inspection axis, and its roll about
that line stays near the planned one. `cone` draws that, in the allocentric frame (the attitude as seen
along the line of sight, which is what the image shows wherever the target sits in the frame):

    R_allo = Rz(roll) · Rtilt(theta, phi) · R_nominal,   R = R_ray(t) · R_allo

Rtilt turns by theta about an axis perpendicular to the line of sight (azimuth phi uniform), with cos theta
uniform in [cos max_angle, 1], so the direction towards the camera in the target's frame is uniform
over the spherical cap of half-angle max_angle about the nominal one; roll is uniform over its range.
R_ray(t) turns the optical axis onto the ray towards the target (no roll about the axis between them).
Pure functions; sample i's draw comes from its own (seed, i, "pose") stream.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from scgen.errors import ScgenError
from scgen.scenes.config.checks import check_choice, check_range, is_number
from scgen.scenes.geometry import quat_to_matrix, random_rotation

POSE_DISTRIBUTIONS = ("uniform", "cone")
CONE_COLUMNS = ("pose_cone_deg", "pose_roll_deg")  # metadata.csv columns of a cone dataset
OPTICAL_AXIS = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class ConeDraw:
    """Where a cone sample sits in its corridor: the tilt of its line of sight from the nominal one and
    its roll about that line (degrees)."""

    cone_deg: float
    roll_deg: float

    def labels(self) -> dict[str, float]:
        """The metadata.csv columns (CONE_COLUMNS) of this draw."""
        return dict(zip(CONE_COLUMNS, (self.cone_deg, self.roll_deg), strict=True))


def check_pose(pose: dict[str, Any]) -> None:
    """The `pose` table: a known distribution, a unit-normable nominal quaternion, a cone angle in
    [0, 180] and an ordered roll range within [-180, 180]."""
    check_choice("pose.distribution", pose["distribution"], POSE_DISTRIBUTIONS)
    q = pose["nominal"]
    if len(q) != 4 or not all(map(is_number, q)) or not np.linalg.norm(np.asarray(q, float)) > 0:
        raise ScgenError(f"pose.nominal must be a non-zero quaternion [w, x, y, z], got {q!r}")
    angle = pose["max_angle_deg"]
    if not is_number(angle) or not 0.0 <= angle <= 180.0:
        raise ScgenError(f"pose.max_angle_deg must lie in [0, 180], got {angle!r}")
    check_range("pose.roll_deg", pose["roll_deg"], -180.0)
    if pose["roll_deg"][1] > 180.0:
        raise ScgenError(f"pose.roll_deg must lie within [-180, 180], got {pose['roll_deg']}")


def ray_rotation(t: np.ndarray) -> np.ndarray:
    """The rotation taking the optical axis onto the ray towards `t` about their common perpendicular:
    egocentric R = ray_rotation(t) @ allocentric R (posenet.geometry.ray_rotation, in numpy)."""
    ray = np.asarray(t, dtype=np.float64) / np.linalg.norm(t)
    axis = np.cross(OPTICAL_AXIS, ray)
    angle = np.arctan2(np.linalg.norm(axis), ray[2])
    if angle == 0.0:
        return np.eye(3)
    return Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix()


def nominal_rotation(pose: dict[str, Any]) -> np.ndarray:
    """The nominal allocentric attitude (model -> camera, the target on the optical axis)."""
    q = np.asarray(pose["nominal"], dtype=np.float64)
    return quat_to_matrix(q / np.linalg.norm(q))


def sample_attitude(
    rng: np.random.Generator, pose: dict[str, Any], t: np.ndarray
) -> tuple[np.ndarray, ConeDraw | None]:
    """The egocentric rotation of a target at `t` drawn from the `pose` table, and its cone draw (None
    for `uniform`, whose draw is the one every earlier dataset used)."""
    if pose["distribution"] == "uniform":
        return random_rotation(rng), None
    cos_max = np.cos(np.deg2rad(pose["max_angle_deg"]))
    theta = float(np.arccos(1.0 - rng.uniform() * (1.0 - cos_max)))
    phi = rng.uniform(0.0, 2 * np.pi)
    roll = float(rng.uniform(*pose["roll_deg"]))
    tilt = Rotation.from_rotvec(theta * np.array([np.cos(phi), np.sin(phi), 0.0]))
    twist = Rotation.from_rotvec(np.deg2rad(roll) * OPTICAL_AXIS)
    R_allo = (twist * tilt).as_matrix() @ nominal_rotation(pose)
    return ray_rotation(t) @ R_allo, ConeDraw(float(np.rad2deg(theta)), roll)
