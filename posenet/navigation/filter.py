"""A relative-navigation filter over per-frame pose measurements: a multiplicative extended Kalman filter
(MEKF) of the target's position, velocity, attitude and angular velocity.

State: the target's centre of mass p and its velocity v relative to the camera, in the translation frame
N; the attitude R (body -> A) and the body rate w (body axes, relative to A); the covariance P of the
12-element error state [dp, dv, a, dw] with R = R_hat exp(a) (posenet.navigation.dynamics). In a user's
video N and A are the camera frame; on an orbit whose camera attitude the chaser knows, N is LVLH and A
inertial (`CameraFrames`, one per frame).

A measurement is a frame's pose (R_m, t_m), camera from model as everywhere in posenet, with covariances
in camera axes (posenet.navigation.noise): t_m = R_CN p - R_CM c (c the centre of mass in the model
frame), R_m = R_CA R exp(noise). Each frame:

- predict to its time (coasting through frames without a measurement: the covariance grows);
- gate rotation and translation apart on their innovation (chi-square, 3 dof each, at `gate_prob`), so a
  turned pose does not discard a good translation; where the object declares symmetries, the symmetric
  twin of the measurement that best fits the prediction is the one used (`twin` flag);
- update with the accepted parts (Joseph form), fold the attitude correction into R and reset;
- start, and after `reinit_after` rejections in a row restart a part, only from two measurements that
  agree with each other (an eclipse's or a lost detector's answers jump; a true change of lock holds):
  the start is at the first of the two, updated with the second, so online the first frame has no
  estimate and the smoother's trajectory begins there.

Every step is kept (`history`) for the fixed-interval smoother (posenet.navigation.smoother). Pure numpy.
A frame's linear algebra is on small matrices (3x3 to 18x18), for which OpenBLAS's threads cost more to
wake, ~0.1-1 ms a LAPACK call between other work, than they give: a step holds numpy's and scipy's BLAS
to one thread (`one_blas_thread`, threadpoolctl), 1.7 against 5.6 ms a frame measured side by side.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cache
from typing import Any

import numpy as np
from scipy.stats import chi2

from posenet.navigation.config import NavConfig
from posenet.navigation.dynamics import AttitudeModel, TranslationModel
from posenet.navigation.so3 import exp, log, skew

POS, VEL, ATT, RATE = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12)
DIM = 12  # the target's error state; a filter with a measurement bias adds BIAS_DIM
BIAS_ROT, BIAS_T = slice(12, 15), slice(15, 18)  # the bias states, where there are
BIAS_DIM = 6
I3 = np.eye(3)


@dataclass(frozen=True)
class CameraFrames:
    """What the chaser knows of its camera at a frame's time: its attitude in the translation frame N
    and in the attitude frame A (camera -> N, camera -> A), its rates relative to them (camera axes,
    rad/s), and the known acceleration of the target relative to the camera (N axes, m/s^2: the chaser's
    own thrust, negated). The default, the camera frame itself, is a user's video."""

    R_nc: np.ndarray = field(default_factory=lambda: I3.copy())
    R_ac: np.ndarray = field(default_factory=lambda: I3.copy())
    w_cn: np.ndarray = field(default_factory=lambda: np.zeros(3))
    w_ca: np.ndarray = field(default_factory=lambda: np.zeros(3))
    accel_n: np.ndarray = field(default_factory=lambda: np.zeros(3))


CAMERA = CameraFrames()


@dataclass(frozen=True)
class Measurement:
    """A frame's pose (camera from model; t in metres) and its noise covariances in camera axes: of the
    rotation error log(R_m R_true^T) (rad^2) and of t (m^2)."""

    R: np.ndarray
    t: np.ndarray
    cov_rot: np.ndarray
    cov_t: np.ndarray


@dataclass(frozen=True)
class MeasurementBias:
    """The persistent part of a network's error (posenet.navigation.noise): what a sequence of similar
    views shares, so that no number of its frames averages it away. A first-order Gauss-Markov process
    per part, in camera axes: the rotation error's (rad) and the translation error's per unit depth, with
    their stationary covariances and correlation times (s)."""

    cov_rot: np.ndarray
    cov_t_rel: np.ndarray
    tau_rot: float
    tau_t: float

    def step(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """(Phi, Q) of the bias states over dt: exp(-dt / tau) and (1 - exp(-2 dt / tau)) cov."""
        phi, Q = np.zeros((BIAS_DIM, BIAS_DIM)), np.zeros((BIAS_DIM, BIAS_DIM))
        parts = ((slice(0, 3), self.cov_rot, self.tau_rot), (slice(3, 6), self.cov_t_rel, self.tau_t))
        for block, cov, tau in parts:
            decay = float(np.exp(-dt / tau)) if tau > 0 else 0.0  # a part with nothing persistent: none
            phi[block, block] = decay * I3
            Q[block, block] = (1.0 - decay**2) * np.asarray(cov)
        return phi, Q


@dataclass(frozen=True)
class NavState:
    """The nominal state and its error covariance at `time` (s); `b` the measurement bias (rotation,
    translation per unit depth; empty without a bias model)."""

    time: float
    p: np.ndarray
    v: np.ndarray
    R: np.ndarray
    w: np.ndarray
    P: np.ndarray
    b: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def plus(self, dx: np.ndarray) -> NavState:
        """The state moved by an error-state vector: R by exp(a) on the right, the rest added."""
        return replace(self, p=self.p + dx[POS], v=self.v + dx[VEL], R=self.R @ exp(dx[ATT]),
                       w=self.w + dx[RATE], b=self.b + dx[DIM:])  # fmt: skip

    def minus(self, other: NavState) -> np.ndarray:
        """The error-state vector from `other` to this state: plus's inverse."""
        return np.concatenate([self.p - other.p, self.v - other.v, log(other.R.T @ self.R), self.w - other.w,
                               self.b - other.b])  # fmt: skip


@dataclass(frozen=True)
class Step:
    """One frame through the filter: the prior (None before the start), the transition from the step
    before, the posterior (the prior when coasting), the frames, and what happened to the measurement:
    each part accepted or not, the symmetric twin used, NIS of each part, and whether a part restarted
    (which cuts the smoother's chain there)."""

    time: float
    frames: CameraFrames
    prior: NavState | None
    phi: np.ndarray | None
    posterior: NavState | None
    measured: bool = False
    accepted_rot: bool = False
    accepted_t: bool = False
    twin: int = 0
    nis_rot: float | None = None
    nis_t: float | None = None
    restarted: bool = False

    @property
    def coasting(self) -> bool:
        """No measurement went in: none came, or every part was rejected."""
        return self.posterior is not None and not (self.accepted_rot or self.accepted_t)

    @property
    def rejected(self) -> bool:
        """A measurement came and a part of it was gated out."""
        return self.measured and self.posterior is not None and not (self.accepted_rot and self.accepted_t)


class PoseFilter:
    """The MEKF of a target with centre of mass `centre_of_mass` (model frame, m) and diameter `diameter`
    (m), its symmetries (K, 4, 4; identity first: X -> S X shows the same view), under `translation` and
    `attitude` models; with `bias`, the measurements' persistent error is estimated beside the state (six
    more states: the pose a measurement gives is the truth plus that bias plus white noise).
    `step(time, frames, measurement)` runs one frame; `history` holds every step."""

    def __init__(
        self,
        translation: TranslationModel,
        attitude: AttitudeModel,
        centre_of_mass: np.ndarray,
        diameter: float,
        symmetries: np.ndarray | None = None,
        config: NavConfig | None = None,
        bias: MeasurementBias | None = None,
    ) -> None:
        self.translation, self.attitude, self.config = translation, attitude, config or NavConfig()
        self.bias = bias
        self.dim = DIM + (BIAS_DIM if bias is not None else 0)
        self.c = np.asarray(centre_of_mass, np.float64)
        self.diameter = float(diameter)
        self.symmetries = np.eye(4)[None] if symmetries is None else np.asarray(symmetries, np.float64)
        self.gate = float(chi2.ppf(self.config.gate_prob, 3))
        self.state: NavState | None = None
        self.history: list[Step] = []
        # the start's first half: a measurement, its frame's time and frames, and its step's index in history
        self._candidate: tuple[float, CameraFrames, Measurement, int] | None = None
        self._rejections = {"rot": 0, "t": 0}
        self._rejected: dict[str, tuple[float, CameraFrames, Measurement] | None] = {"rot": None, "t": None}

    @classmethod
    def for_motion(
        cls,
        centre_of_mass: np.ndarray,
        diameter: float,
        symmetries: np.ndarray | None = None,
        mean_motion: float | None = None,
        inertia: np.ndarray | None = None,
        config: NavConfig | None = None,
        bias: MeasurementBias | None = None,
    ) -> PoseFilter:
        """A filter whose dynamics are HCW at `mean_motion` (else constant velocity) and torque-free with
        `inertia` (else constant angular velocity), with the process noise of `config` in the target's
        diameters, and the measurements' `bias` model (None: white measurement noise)."""
        cfg = config or NavConfig()
        translation = TranslationModel(mean_motion, (cfg.accel_noise * diameter) ** 2)
        attitude = AttitudeModel(None if inertia is None else np.asarray(inertia, np.float64),
                                 cfg.angular_accel_noise**2)  # fmt: skip
        return cls(translation, attitude, centre_of_mass, diameter, symmetries, cfg, bias)

    def start_from(self, state: NavState, frames: CameraFrames = CAMERA) -> Step:
        """Start the track at a known state (another sensor's, or a test's truth) instead of from two
        agreeing measurements."""
        self.reset()
        self.state = state
        step = Step(state.time, frames, None, None, state, accepted_rot=True, accepted_t=True, restarted=True)
        self.history.append(step)
        return step

    def reset(self) -> None:
        """Forget the track (a new sequence)."""
        self.state, self.history, self._candidate = None, [], None
        self._rejections, self._rejected = {"rot": 0, "t": 0}, {"rot": None, "t": None}

    # -----------------------------------------------------------------------------------------------------
    # one frame

    def predict(self, time: float, frames: CameraFrames = CAMERA) -> tuple[NavState, np.ndarray] | None:
        """The state at `time` (not kept), and the error-state transition to it; None before the start."""
        with one_blas_thread():
            return self._predict(time, frames)

    def _predict(self, time: float, frames: CameraFrames) -> tuple[NavState, np.ndarray] | None:
        if self.state is None:
            return None
        s = self.state
        dt = float(time) - s.time
        if dt < 0:
            raise ValueError(f"frame times must not decrease: {time} s after {s.time} s")
        phi_t, gamma, Q_t = self.translation.step(dt)
        before = self.history[-1].frames.accel_n if self.history else frames.accel_n
        u = 0.5 * (np.asarray(before, np.float64) + np.asarray(frames.accel_n))  # first-order hold
        pv = phi_t @ np.concatenate([s.p, s.v]) + gamma @ u
        R, w, phi_a, Q_a = self.attitude.step(s.R, s.w, dt)
        phi, Q = np.zeros((self.dim, self.dim)), np.zeros((self.dim, self.dim))
        phi[:6, :6], phi[6:DIM, 6:DIM] = phi_t, phi_a
        Q[:6, :6], Q[6:DIM, 6:DIM] = Q_t, Q_a
        b = s.b
        if self.bias is not None:
            phi_b, Q_b = self.bias.step(dt)
            phi[DIM:, DIM:], Q[DIM:, DIM:] = phi_b, Q_b
            b = phi_b @ s.b
        P = phi @ s.P @ phi.T + Q
        return NavState(float(time), pv[:3], pv[3:], R, w, 0.5 * (P + P.T), b), phi

    def step(
        self,
        time: float,
        frames: CameraFrames = CAMERA,
        measurement: Measurement | None = None,
        predicted: tuple[NavState, np.ndarray] | None = None,
    ) -> Step:
        """Run the frame at `time`: predict (or take `predicted`, this filter's own `predict(time, frames)`
        made for the frame already), then update with `measurement` (None: coast)."""
        with one_blas_thread():
            return self._step(float(time), frames, measurement, predicted)

    def _step(
        self,
        time: float,
        frames: CameraFrames,
        measurement: Measurement | None,
        predicted: tuple[NavState, np.ndarray] | None,
    ) -> Step:
        if predicted is None:
            predicted = self._predict(time, frames)
        if predicted is None:
            step = self._start(float(time), frames, measurement)
        else:
            prior, phi = predicted
            step = Step(float(time), frames, prior, phi, prior)
            if measurement is not None:
                step = self._update(step, measurement)
            self.state = step.posterior
        self.history.append(step)
        return step

    # -----------------------------------------------------------------------------------------------------
    # the update

    def expected(self, state: NavState, frames: CameraFrames) -> tuple[np.ndarray, np.ndarray]:
        """The pose the state puts the target at: (R_CM, t) in the camera frame."""
        R_cm = frames.R_ac.T @ state.R
        return R_cm, frames.R_nc.T @ state.p - R_cm @ self.c

    def _measured(self, state: NavState, frames: CameraFrames) -> tuple[np.ndarray, np.ndarray]:
        """The pose a measurement should show in the state: `expected`, plus the bias where there is one
        (exp(b_R) R_CM and t + z b_t)."""
        R_cm, t = self.expected(state, frames)
        if self.bias is None:
            return R_cm, t
        return exp(state.b[:3]) @ R_cm, t + t[2] * state.b[3:]

    def _twins(self, m: Measurement) -> list[tuple[np.ndarray, np.ndarray]]:
        """The measurement and its symmetric twins (R S_R, t + R S_t): the same image, the same fit."""
        return [(m.R @ S[:3, :3], m.t + m.R @ S[:3, 3]) for S in self.symmetries]

    def _update(self, step: Step, m: Measurement) -> Step:
        prior, frames = step.prior, step.frames
        assert prior is not None
        R_true, t_true = self.expected(prior, frames)
        R_cm, t_hat = self._measured(prior, frames)
        H_rot, H_t = np.zeros((3, self.dim)), np.zeros((3, self.dim))
        H_rot[:, ATT] = I3
        H_t[:, POS], H_t[:, ATT] = frames.R_nc.T, R_true @ skew(self.c)
        if self.bias is not None:  # the bias moves the measured pose (to first order in the bias)
            H_rot[:, BIAS_ROT] = R_cm.T
            H_t[:, BIAS_T] = t_true[2] * I3
            H_t[:, POS] += np.outer(prior.b[3:], frames.R_nc.T[2])  # z b_t moves with the depth
        N_rot, N_t = R_cm.T @ m.cov_rot @ R_cm, m.cov_t
        S_rot = H_rot @ prior.P @ H_rot.T + N_rot
        S_t = H_t @ prior.P @ H_t.T + N_t
        best = None  # (nis of the rotation, twin index, its R, its t)
        for k, (R_m, t_m) in enumerate(self._twins(m)):
            r = log(R_cm.T @ R_m)
            nis = float(r @ np.linalg.solve(S_rot, r))
            if best is None or nis < best[0]:
                best = (nis, k, R_m, t_m)
        nis_rot, twin, R_m, t_m = best  # type: ignore[misc]
        r_t = t_m - t_hat
        nis_t = float(r_t @ np.linalg.solve(S_t, r_t))
        ok_rot, ok_t = nis_rot <= self.gate, nis_t <= self.gate
        rows, residual, noise = [], [], []
        if ok_rot:
            rows.append(H_rot), residual.append(log(R_cm.T @ R_m)), noise.append(N_rot)
        if ok_t:
            rows.append(H_t), residual.append(r_t), noise.append(N_t)
        posterior = prior
        if rows:
            H, r = np.vstack(rows), np.concatenate(residual)
            N = np.zeros((len(r), len(r)))
            for i, block in enumerate(noise):
                N[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = block
            posterior = kalman_update(prior, H, r, N)
        step = replace(step, posterior=posterior, measured=True, accepted_rot=ok_rot, accepted_t=ok_t,
                       twin=twin if ok_rot else 0, nis_rot=nis_rot, nis_t=nis_t)  # fmt: skip
        return self._restart_if_locked(step, m)

    # -----------------------------------------------------------------------------------------------------
    # the start and restarts

    def _initial_state(self, time: float, frames: CameraFrames, m: Measurement) -> NavState:
        """The state one measurement gives: its pose, no motion, the priors' spread on the rates; with a
        bias model, no bias, whose spread the pose shares (the pose's error is minus bias and noise)."""
        cfg = self.config
        P = np.zeros((self.dim, self.dim))
        z = float(m.t[2])
        P[POS, POS] = frames.R_nc @ m.cov_t @ frames.R_nc.T
        P[VEL, VEL] = (cfg.velocity_prior * self.diameter) ** 2 * I3
        P[ATT, ATT] = m.R.T @ m.cov_rot @ m.R
        P[RATE, RATE] = np.radians(cfg.rate_prior_deg) ** 2 * I3
        if self.bias is not None:
            B_rot, B_t = np.asarray(self.bias.cov_rot), np.asarray(self.bias.cov_t_rel)
            P[ATT, ATT] += m.R.T @ B_rot @ m.R
            P[ATT, BIAS_ROT] = -m.R.T @ B_rot
            P[BIAS_ROT, BIAS_ROT] = B_rot
            P[POS, POS] += z * z * frames.R_nc @ B_t @ frames.R_nc.T
            P[POS, BIAS_T] = -z * frames.R_nc @ B_t
            P[BIAS_T, BIAS_T] = B_t
            P = np.triu(P) + np.triu(P, 1).T
        R_ab = frames.R_ac @ m.R
        p = frames.R_nc @ (m.t + m.R @ self.c)
        return NavState(time, p, np.zeros(3), R_ab, np.zeros(3), P, np.zeros(self.dim - DIM))

    def agree(
        self, a: tuple[float, CameraFrames, Measurement], b: tuple[float, CameraFrames, Measurement]
    ) -> bool:
        """Whether two measurements (time, frames, measurement) fit one motion within the priors: each
        part's difference inside the gate of their noise plus what the prior rates allow over the time
        between them (the twin of b closest to a counts)."""
        (ta, fa, ma), (tb, fb, mb) = a, b
        dt, cfg = abs(tb - ta), self.config
        turn = (np.radians(cfg.rate_prior_deg) * dt) ** 2 * I3
        move = (cfg.velocity_prior * self.diameter * dt) ** 2 * I3
        Ra, Rb = fa.R_ac @ ma.R, fb.R_ac @ mb.R  # in A: the camera's own turn is known
        pa, pb = fa.R_nc @ (ma.t + ma.R @ self.c), fb.R_nc @ (mb.t + mb.R @ self.c)
        S_rot = (
            Ra.T @ fa.R_ac @ ma.cov_rot @ fa.R_ac.T @ Ra + Rb.T @ fb.R_ac @ mb.cov_rot @ fb.R_ac.T @ Rb + turn
        )
        S_t = fa.R_nc @ ma.cov_t @ fa.R_nc.T + fb.R_nc @ mb.cov_t @ fb.R_nc.T + move
        d = pb - pa
        if float(d @ np.linalg.solve(S_t, d)) > self.gate:
            return False
        for S in self.symmetries:
            r = log(Ra.T @ Rb @ S[:3, :3])
            if float(r @ np.linalg.solve(S_rot, r)) <= self.gate:
                return True
        return False

    def _start(self, time: float, frames: CameraFrames, m: Measurement | None) -> Step:
        """Before the start: keep a measurement; on one that agrees with the one kept, start at the kept
        one's frame (its step, already in `history`, gets that state: the smoother sees it, the online
        estimate of that frame stays none) and update with this one as any frame after the start."""
        step = Step(time, frames, None, None, None, measured=m is not None)
        if m is None:
            return step
        here = (time, frames, m)
        kept, self._candidate = self._candidate, None
        if kept is None or not self.agree(kept[:3], here):
            self._candidate = (*here, len(self.history))
            return step
        t0, f0, m0, index = kept
        self.state = self._initial_state(t0, f0, m0)
        self.history[index] = replace(self.history[index], posterior=self.state, accepted_rot=True,
                                      accepted_t=True, restarted=True)  # fmt: skip
        predicted = self._predict(time, frames)
        assert predicted is not None
        prior, phi = predicted
        return self._update(Step(time, frames, prior, phi, prior), m)

    def _restart_if_locked(self, step: Step, m: Measurement) -> Step:
        """After `reinit_after` rejections of a part in a row, restart that part from the measurement
        if it agrees with the rejected one before (a lock on a wrong pose, or a jump that holds)."""
        assert step.posterior is not None
        state, restarted = step.posterior, False
        here = (step.time, step.frames, m)
        for part, accepted in (("rot", step.accepted_rot), ("t", step.accepted_t)):
            if accepted:
                self._rejections[part], self._rejected[part] = 0, None
                continue
            self._rejections[part] += 1
            before, self._rejected[part] = self._rejected[part], here
            if (
                self._rejections[part] >= self.config.reinit_after
                and before is not None
                and self.agree(before, here)
            ):
                fresh = self._initial_state(step.time, step.frames, m)
                state = _restart_part(state, fresh, part)
                self._rejections[part], self._rejected[part], restarted = 0, None, True
        return replace(step, posterior=state, restarted=step.restarted or restarted)


@cache
def _blas() -> Any:
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def one_blas_thread() -> Any:
    """A context holding numpy's and scipy's BLAS (OpenBLAS) to one thread: on the filter's small
    matrices waking a second one costs more than it gives."""
    return _blas().limit(limits=1, user_api="blas")


def kalman_update(prior: NavState, H: np.ndarray, r: np.ndarray, N: np.ndarray) -> NavState:
    """The posterior of `prior` after residual r = H dx + noise(N): Joseph form, the attitude correction
    folded into R and the covariance reset to the new attitude (G = I - [a/2]x on the attitude block)."""
    P = prior.P
    n = len(P)
    S = H @ P @ H.T + N
    K = np.linalg.solve(S, H @ P).T  # P H^T S^-1, S symmetric
    dx = K @ r
    A = np.eye(n) - K @ H
    P = A @ P @ A.T + K @ N @ K.T
    G = np.eye(n)
    G[ATT, ATT] = I3 - 0.5 * skew(dx[ATT])
    P = G @ P @ G.T
    return replace(prior.plus(dx), P=0.5 * (P + P.T))


def _restart_part(state: NavState, fresh: NavState, part: str) -> NavState:
    """`state` with its rotation (attitude, rate and rotation bias) or translation (position, velocity
    and translation bias) taken from `fresh`, and that part's covariance uncorrelated with the rest."""
    n = len(state.P)
    blocks = (ATT, RATE, BIAS_ROT) if part == "rot" else (POS, VEL, BIAS_T)
    taken = np.zeros(n, bool)
    for block in blocks:
        taken[block] = block.start < n
    P = state.P.copy()
    P[taken, :], P[:, taken] = 0.0, 0.0
    P[np.ix_(taken, taken)] = fresh.P[np.ix_(taken, taken)]
    b = state.b.copy()
    if len(b):
        b[slice(0, 3) if part == "rot" else slice(3, 6)] = 0.0
    if part == "rot":
        return replace(state, R=fresh.R, w=fresh.w, P=P, b=b)
    return replace(state, p=fresh.p, v=fresh.v, P=P, b=b)
