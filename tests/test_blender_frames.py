"""OpenCV -> Blender frame conversions (pure math, no bpy)."""

from __future__ import annotations

import numpy as np
import pytest

from scgen.errors import ScgenError
from scgen.render.blender.frames import camera_matrix_world, intrinsics_from_K, light_matrix_world
from scgen.scenes.geometry import random_rotation


def test_camera_matrix_maps_world_points_into_the_blender_camera_frame():
    rng = np.random.default_rng(1)
    R, t = random_rotation(rng), rng.normal(size=3)
    m = camera_matrix_world(R, t)
    X = rng.normal(size=(10, 3))
    local = (X - m[:3, 3]) @ m[:3, :3]  # world -> Blender camera coordinates
    opencv = X @ R.T + t
    np.testing.assert_allclose(local, opencv * [1, -1, -1], atol=1e-12)  # Blender: y up, looks along -z
    np.testing.assert_allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-12)


def test_identity_pose_is_the_flip_about_x():
    m = camera_matrix_world(np.eye(3), np.zeros(3))
    np.testing.assert_array_equal(m, np.diag([1.0, -1.0, -1.0, 1.0]))  # (F I)^T and -I^T 0: exact


def test_intrinsics_from_K():
    K = np.array([[600.0, 0, 300.25], [0, 600.0, 260.75], [0, 0, 1]])
    intr = intrinsics_from_K(K, 640, 480)
    # the same float64 operations as intrinsics_from_K (640 / 2 - 0.5 = 319.5 and 480 / 2 - 0.5 = 239.5
    # exactly): the same floats
    assert intr.lens_mm == 600 * intr.sensor_width_mm / 640
    assert intr.shift_x == (319.5 - 300.25) / 640
    assert intr.shift_y == (260.75 - 239.5) / 640
    centred = intrinsics_from_K(np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]]), 640, 480)
    assert centred.shift_x == centred.shift_y == 0.0


SKEWED = [[600, 1, 320], [0, 600, 240], [0, 0, 1]]
NON_SQUARE = [[600, 0, 320], [0, 590, 240], [0, 0, 1]]


@pytest.mark.parametrize("K", [SKEWED, NON_SQUARE])
def test_skew_and_non_square_pixels_are_refused(K):
    with pytest.raises(ScgenError, match="square pixels"):
        intrinsics_from_K(np.array(K, float), 640, 480)


def test_sun_points_its_local_z_at_the_light():
    d = np.array([0.3, -0.5, 0.8])
    m = light_matrix_world(d)
    np.testing.assert_array_equal(m[:3, 2], d / np.linalg.norm(d))  # its z column is that very quotient
    # x and y: a cross product and a normalisation of unit vectors, a few u64 (1.1e-16) an entry, so the
    # Gram matrix and the determinant within ~1e-15 of I and 1, where a left-handed frame's det is -1
    np.testing.assert_allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.det(m[:3, :3]) == pytest.approx(1.0, abs=1e-12)
