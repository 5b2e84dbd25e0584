"""OpenCV frames -> Blender: camera pose, exact intrinsics from K, light orientation (pure math, no bpy).

OpenCV looks along +z with +y down; a Blender camera looks along its local -z with +y up, so the
two frames differ by F = diag(1, -1, -1). Blender's view plane is fitted to the sensor width
(sensor_fit HORIZONTAL) and both lens shifts are in units of the image width. Non-square pixels
(fx != fy) are refused: they need a render pixel aspect, and Blender 5.0 then fails to write the
multilayer EXR ("Conflicting attributes ... pixelAspectRatio").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scgen.errors import ScgenError

OPENCV_TO_BLENDER = np.diag([1.0, -1.0, -1.0])
SENSOR_WIDTH_MM = 36.0


def camera_matrix_world(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Blender camera `matrix_world` (4x4) for the OpenCV world -> camera pose X_cam = R X + t."""
    R = np.asarray(R, np.float64)
    m = np.eye(4)
    m[:3, :3] = (OPENCV_TO_BLENDER @ R).T
    m[:3, 3] = -R.T @ np.asarray(t, np.float64)
    return m


@dataclass(frozen=True)
class BlenderIntrinsics:
    """Blender camera settings reproducing a pinhole K exactly (pixel centres at integers)."""

    lens_mm: float
    sensor_width_mm: float
    shift_x: float
    shift_y: float


def intrinsics_from_K(K: np.ndarray, width: int, height: int) -> BlenderIntrinsics:
    """Blender settings for K; raises ScgenError for skew or fx != fy (see the module docstring)."""
    K = np.asarray(K, np.float64)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if fx <= 0 or abs(K[0, 1]) > 1e-9 * fx or abs(fx - fy) > 1e-9 * fx:
        raise ScgenError(
            "the blender backend needs square pixels and zero skew (fx == fy > 0, K[0,1] == 0), "
            f"got K={K.tolist()}"
        )
    return BlenderIntrinsics(
        lens_mm=fx * SENSOR_WIDTH_MM / width,
        sensor_width_mm=SENSOR_WIDTH_MM,
        shift_x=(width / 2 - 0.5 - cx) / width,
        shift_y=(cy - (height / 2 - 0.5)) / width,
    )


def light_matrix_world(direction: np.ndarray) -> np.ndarray:
    """`matrix_world` (4x4) of a Blender sun shining from `direction` (unit, towards the light).

    A sun lamp emits along its local -z, so its local +z is the direction towards the light.
    """
    z = np.asarray(direction, np.float64)
    z = z / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    m = np.eye(4)
    m[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
    return m
