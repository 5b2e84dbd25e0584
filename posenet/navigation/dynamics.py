"""The motion models the filter predicts with: the target's translation relative to the camera and its
attitude, each with its process noise.

Translation (`TranslationModel`), state [p; v] of the target's centre of mass relative to the camera in
a frame N: with the orbit's mean motion n, N is the chaser's LVLH frame and [p; v] obeys the Hill-
Clohessy-Wiltshire equations (scgen.scenes.motion.orbit.hcw_stm, the dynamics scgen simulates; p = -r is
as linear as the chaser's r); without one, N is the camera frame and the motion is at constant velocity.
A known acceleration u (the chaser's own thrust, negated) enters as an input. The unmodelled acceleration
is white with power spectral density `accel_psd` (m^2/s^3) per axis; its discrete covariance and the
input's gain are integrals of Phi(s) over the step, taken by Simpson's rule (exact for constant velocity,
and for HCW within (n dt)^4 ~ 1e-11 at a 2 s step in low orbit).

Attitude (`AttitudeModel`), nominal R (body -> A) and body rate w (body axes, relative to A), with the
multiplicative error R = R_hat exp(a) (a in body axes): torque-free with the body's inertia tensor J
(Euler's equations, scgen.scenes.motion.tumble.euler_rates; A is then inertial), or at constant angular
velocity. The error state [a; dw] obeys a' = -[w]x a + dw, dw' = F_w dw + noise, F_w = J^-1 ([J w]x -
[w]x J) (zero at constant rate), with white angular acceleration of PSD `accel_psd` (rad^2/s^3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.linalg import expm

from posenet.navigation.so3 import exp, skew
from scgen.scenes.motion.orbit import hcw_stm
from scgen.scenes.motion.tumble import euler_rates

SIMPSON_NODES = 9  # quadrature nodes over a step for the input gain and the process noise (odd)
MAX_TURN_RAD = 0.01  # torque-free nominal propagation: sub-steps turning at most this much each (RK4)


def _simpson(values: np.ndarray, span: float) -> np.ndarray:
    """Simpson's rule over equally spaced samples (first axis, an odd count) spanning `span`."""
    weights = np.ones(len(values))
    weights[1:-1:2], weights[2:-1:2] = 4.0, 2.0
    return np.tensordot(weights, values, axes=1) * span / (3.0 * (len(values) - 1))


@dataclass(frozen=True)
class TranslationModel:
    """Relative translation [p; v] (m, m/s): HCW at `mean_motion` (rad/s), or constant velocity (None)."""

    mean_motion: float | None
    accel_psd: float

    def stm(self, dt: np.ndarray | float) -> np.ndarray:
        """Phi(dt) ((..., 6, 6)): [p; v](t + dt) = Phi(dt) [p; v](t) in free motion."""
        dt = np.asarray(dt, np.float64)
        if self.mean_motion is not None and self.mean_motion > 0:
            return hcw_stm(self.mean_motion, dt)
        out = np.broadcast_to(np.eye(6), dt.shape + (6, 6)).copy()
        out[..., :3, 3:] = dt[..., None, None] * np.eye(3)
        return out

    def step(self, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(Phi, Gamma, Q) over dt: Gamma (6x3) takes a constant input acceleration over the step into the
        state, Q (6x6) the unmodelled acceleration's covariance: integrals over s in [0, dt] of
        Phi(s)[:, 3:] and of accel_psd Phi(s)[:, 3:] Phi(s)[:, 3:]^T."""
        phis = self.stm(np.linspace(0.0, dt, SIMPSON_NODES))[..., 3:]
        gamma = _simpson(phis, dt)
        Q = self.accel_psd * _simpson(phis @ np.swapaxes(phis, -1, -2), dt)
        return self.stm(dt), gamma, 0.5 * (Q + Q.T)


@dataclass(frozen=True)
class AttitudeModel:
    """Attitude and body rate: torque-free with `inertia` (3x3, any unit: only its ratios act), or at
    constant angular velocity (None)."""

    inertia: np.ndarray | None
    accel_psd: float

    @cached_property
    def inverse_inertia(self) -> np.ndarray | None:
        return None if self.inertia is None else np.linalg.inv(self.inertia)

    def rate_jacobian(self, w: np.ndarray) -> np.ndarray:
        """d(w')/dw of Euler's equations at w (zero at constant rate)."""
        if self.inertia is None or self.inverse_inertia is None:
            return np.zeros((3, 3))
        J = self.inertia
        return self.inverse_inertia @ (skew(J @ w) - skew(w) @ J)

    def step(
        self, R: np.ndarray, w: np.ndarray, dt: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(R', w', Phi, Q) over dt: the nominal attitude and rate after dt (exact at constant rate; RK4 on
        Euler's equations in sub-steps of at most MAX_TURN_RAD otherwise, the attitude turned by each
        sub-step's mean rate: the midpoint rule, whose global error over T is at most T h^2 / 12 times
        max |w x w'|, h a sub-step), the error-state transition (6x6, [a; dw]: the matrix exponential of
        the error dynamics at the step's mean rate, which is all a covariance needs) and the process
        noise."""
        w = np.asarray(w, np.float64)
        if self.inertia is None:
            R_next, w_next = R @ exp(w * dt), w
        else:
            J, J_inv = self.inertia, self.inverse_inertia
            steps = max(1, math.ceil(np.linalg.norm(w) * abs(dt) / MAX_TURN_RAD))
            h, R_next, w_next = dt / steps, R, w
            for _ in range(steps):
                k1 = euler_rates(J, w_next, J_inv)
                k2 = euler_rates(J, w_next + 0.5 * h * k1, J_inv)
                k3 = euler_rates(J, w_next + 0.5 * h * k2, J_inv)
                k4 = euler_rates(J, w_next + h * k3, J_inv)
                w_end = w_next + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
                R_next = R_next @ exp(0.5 * h * (w_next + w_end))
                w_next = w_end
        mean = 0.5 * (w + w_next)
        F = np.zeros((6, 6))
        F[:3, :3], F[:3, 3:], F[3:, 3:] = -skew(mean), np.eye(3), self.rate_jacobian(mean)
        phi = expm(F * dt)
        return R_next, w_next, phi, white_acceleration_noise(self.accel_psd, dt)


def white_acceleration_noise(psd: float, dt: float) -> np.ndarray:
    """The discrete covariance (6x6) over dt of [angle; rate] driven by white acceleration of PSD `psd`
    per axis: psd [[dt^3/3, dt^2/2], [dt^2/2, dt]] (x) I3 (the attitude's own turn over the step left out,
    |w| dt << 1)."""
    return psd * np.kron(np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]), np.eye(3))
