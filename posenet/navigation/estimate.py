"""A filter state as a user reads it: the pose, velocity and angular velocity in the camera frame at a
frame's time, with their covariance.

Outputs, camera axes (as scgen labels a sequence frame, docs/sequences.md): R (camera from model) and t
(the model origin, m); the velocity dt/dt (m/s) and the target's angular velocity relative to the camera
w (rad/s, dR/dt = [w]x R). With the state's p, v (N), R_AB, w_B and the camera's frames:

    R = R_CA R_AB,    t = R_CN p - R c,    w = R w_B - w_CA,
    dt/dt = R_CN v - w_CN x (R_CN p) - w x (R c)

Their covariance is J P J^T, J the Jacobian of these outputs in the error state (`output_jacobian`,
worked out by hand and held to central differences in tests/test_navigation.py); the rotation's error is
the rotation vector of R_true R^T, camera axes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from posenet.navigation.filter import ATT, DIM, POS, RATE, CameraFrames, NavState
from posenet.navigation.filter import VEL as VEL_STATE
from posenet.navigation.so3 import skew

T, ROT, VEL, OMEGA = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12)  # blocks of Estimate.cov


@dataclass(frozen=True)
class Estimate:
    """The pose and motion at `time` in camera axes, and `cov` (12x12) over [t, rotation, velocity, w]."""

    time: float
    R: np.ndarray
    t: np.ndarray
    velocity: np.ndarray
    omega: np.ndarray
    cov: np.ndarray

    def sigma(self, block: slice) -> np.ndarray:
        """The 1-sigma of each axis of a block (T, ROT, VEL, OMEGA)."""
        return np.sqrt(np.clip(np.diag(self.cov[block, block]), 0.0, None))

    def nees(self, block: slice, error: np.ndarray) -> float:
        """error^T cov^-1 error of one block's error (truth minus estimate; rotation: log(R_true R^T))."""
        return float(error @ np.linalg.solve(self.cov[block, block], error))


def output_jacobian(state: NavState, frames: CameraFrames, c: np.ndarray) -> np.ndarray:
    """d[t, rotation, velocity, w] / d[dp, dv, a, dw, bias] at `state` (12 x the state's size; the outputs
    do not depend on a measurement bias): with R = R_CM, the rotation's error in camera axes R a, Rc = R c,
    w = R w_B - w_CA and R exp(a) c ~ Rc - R [c]x a,

        t:   R_CN dp + R [c]x a
        rot: R a
        w:   R dw - R [w_B]x a
        v:   R_CN dv - [w_CN]x R_CN dp + [Rc]x dw_out - [w]x dRc
    """
    R = frames.R_ac.T @ state.R
    R_cn = frames.R_nc.T
    Rc = R @ c
    w = R @ state.w - frames.w_ca
    dw_da, dw_dw = -R @ skew(state.w), R
    dRc_da = -R @ skew(c)
    J = np.zeros((DIM, len(state.P)))
    J[T, POS], J[T, ATT] = R_cn, -dRc_da
    J[ROT, ATT] = R
    J[OMEGA, ATT], J[OMEGA, RATE] = dw_da, dw_dw
    J[VEL, POS], J[VEL, VEL_STATE] = -skew(frames.w_cn) @ R_cn, R_cn
    J[VEL, ATT] = skew(Rc) @ dw_da - skew(w) @ dRc_da
    J[VEL, RATE] = skew(Rc) @ dw_dw
    return J


def camera_estimate(state: NavState, frames: CameraFrames, centre_of_mass: np.ndarray) -> Estimate:
    """`state` in the camera frame of `frames`, with its covariance J P J^T (`output_jacobian`)."""
    c = np.asarray(centre_of_mass, np.float64)
    R = frames.R_ac.T @ state.R
    p_c = frames.R_nc.T @ state.p
    Rc = R @ c
    w = R @ state.w - frames.w_ca
    velocity = frames.R_nc.T @ state.v - np.cross(frames.w_cn, p_c) - np.cross(w, Rc)
    J = output_jacobian(state, frames, c)
    cov = J @ state.P @ J.T
    return Estimate(state.time, R, p_c - Rc, velocity, w, 0.5 * (cov + cov.T))


def state_from_camera(
    time: float,
    R: np.ndarray,
    t: np.ndarray,
    velocity: np.ndarray,
    omega: np.ndarray,
    frames: CameraFrames,
    centre_of_mass: np.ndarray,
    P: np.ndarray,
) -> NavState:
    """The filter state whose camera-frame outputs are (R, t, velocity, omega): the inverse of
    `camera_estimate`, for a track started from a known state (PoseFilter.start_from), with covariance P
    (the error state's; beyond its first 12, a measurement bias's, at none)."""
    Rc = R @ np.asarray(centre_of_mass, np.float64)
    p_c = t + Rc
    v_c = velocity + np.cross(omega, Rc) + np.cross(frames.w_cn, p_c)
    w_b = R.T @ (omega + frames.w_ca)
    bias = np.zeros(len(P) - DIM)  # a filter's measurement bias, if it has one, at none
    return NavState(float(time), frames.R_nc @ p_c, frames.R_nc @ v_c, frames.R_ac @ R, w_b, P, bias)
