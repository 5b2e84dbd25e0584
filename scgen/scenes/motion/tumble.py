"""The target's attitude along a sequence: held in LVLH, inertially fixed, a principal-axis spin, or a
torque-free tumble integrated from Euler's equations with the inertia tensor of its mesh.

Frames: the body frame B is the model frame (its axes; scgen.scenes.model), rotating about the centre of
mass; LVLH and the inertial frame I are those of scgen.scenes.motion.orbit (LVLH turns in I about z at the
mean motion n). Rotations map vectors: R_IB v_B = v_I, R_LB v_B = v_L, with R_LB = R_IL(t)^T R_IB.
Angular velocities are the body's relative to I, in body axes (rad/s). The body turns about its centre
of mass c (model frame, `MassProperties.centre_of_mass`): when the chaser sees the centre of mass at r,
the model origin sits at r - R c.

Torque-free motion obeys Euler's equations in the body frame, with J the inertia tensor about c,

    J w' = -w x (J w),      q' = 1/2 q (x) (0, w)      (q: body -> I, Hamilton, scalar first)

which conserve the angular momentum in I, H = R_IB J w, and the kinetic energy T = 1/2 w . J w.
`integrate_tumble` solves them with scipy's DOP853 at rtol 1e-10, atol 1e-12. Pure numpy/scipy.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from scgen.errors import ScgenError
from scgen.scenes.geometry import random_rotation, random_unit_vector
from scgen.scenes.motion.orbit import lvlh_to_inertial

ATTITUDE_MODES = ("lvlh_hold", "inertial", "spin", "tumble")
SPIN_AXES = ("minor", "intermediate", "major")  # principal axes by ascending moment
STABLE_SPIN_AXES = ("minor", "major")  # the ones a drawn spin uses: a spin about the intermediate one flips
DEFAULT_RATE_DEG = (0.5, 5.0)  # deg/s, drawn spin and tumble rates (SISIFOS tumbles at 3-5 deg/s)
RTOL, ATOL = 1e-10, 1e-12  # the tumble integrator's tolerances (atol on rad/s and on unit quaternions)


# ---------------------------------------------------------------------------------------------------------
# inertia


@dataclass(frozen=True)
class MassProperties:
    """A uniform-density body: centre of mass (model frame, m), inertia about it per unit mass (model
    axes, m^2: torque-free motion depends on its ratios only), principal moments (ascending) and axes
    (columns, a right-handed rotation principal -> model), and `source`: how the mesh gave them."""

    centre_of_mass: np.ndarray
    inertia: np.ndarray
    principal_moments: np.ndarray
    principal_axes: np.ndarray
    source: str

    def axis(self, name: str) -> np.ndarray:
        """The principal axis `name` (minor / intermediate / major moment) in the model frame."""
        if name not in SPIN_AXES:
            raise ScgenError(f"unknown principal axis {name!r}; choose one of {', '.join(SPIN_AXES)}")
        return self.principal_axes[:, SPIN_AXES.index(name)]


def inertia_properties(inertia: np.ndarray, centre_of_mass: np.ndarray, source: str) -> MassProperties:
    """MassProperties of a symmetric positive-definite inertia tensor (any unit)."""
    J = 0.5 * (np.asarray(inertia, np.float64) + np.asarray(inertia, np.float64).T)
    moments, axes = np.linalg.eigh(J)
    if not moments[0] > 0:
        raise ScgenError(f"inertia tensor is not positive definite (moments {moments})")
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1.0
    return MassProperties(np.asarray(centre_of_mass, np.float64), J, moments, axes, source)


def _solid_pieces(mesh: trimesh.Trimesh) -> list[tuple[trimesh.Trimesh, bool]]:
    """The closed pieces of a mesh, each (solid, whether it is a convex hull standing in)."""
    # geometry only (no UVs or normals to keep vertices apart): a GLB splits vertices along its seams,
    # and welding them moves no point
    welded = trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), process=False)
    welded.merge_vertices()
    pieces = [welded] if welded.is_watertight else welded.split(only_watertight=False, repair=False)
    out = []
    for piece in pieces:
        if piece.is_watertight and piece.is_winding_consistent:
            if piece.volume < 0:  # closed but wound inside out: the same solid
                piece.invert()
            out.append((piece, False))
        elif len(np.unique(piece.vertices, axis=0)) >= 4:
            out.append((piece.convex_hull, True))
    return [(p, hull) for p, hull in out if p.volume > 0]  # a flat sheet has no volume, hence no mass


def mass_properties(meshes: trimesh.Trimesh | Sequence[trimesh.Trimesh]) -> MassProperties:
    """Mass properties of one mesh or of parts (a TargetModel's), all of one uniform density.

    Volume integrals are right only over closed, consistently wound surfaces. So each mesh is welded and,
    if not closed, split into its connected pieces; each closed piece counts as it is (turned outward if
    wound inside out), and each open one (a dish, a sheet with a rim) by its convex hull, which fills its
    concavities and so overstates its mass and inertia; flat pieces have no volume and no mass. Parts that
    interpenetrate count their overlap twice. `source` says 'mesh' when every piece was closed, else how
    much of the mass came from hulls: an approximation of the body's tensor, stated, not hidden.
    """
    pieces = [
        p for m in ([meshes] if isinstance(meshes, trimesh.Trimesh) else meshes) for p in _solid_pieces(m)
    ]
    if not pieces:
        raise ScgenError("the mesh encloses no volume: no inertia tensor for a tumble")
    mass = np.array([p.mass for p, _ in pieces])  # density 1: mass = volume
    centres = np.array([p.center_mass for p, _ in pieces])
    com = mass @ centres / mass.sum()
    inertia = np.zeros((3, 3))
    for (p, _), m, c in zip(pieces, mass, centres, strict=True):
        d = c - com  # parallel axes: each piece's tensor about its own centre, moved to the common one
        inertia += np.asarray(p.moment_inertia) + m * (d @ d * np.eye(3) - np.outer(d, d))
    hull_share = mass[[hull for _, hull in pieces]].sum() / mass.sum()
    n_hulls = sum(hull for _, hull in pieces)
    source = (
        "mesh"
        if n_hulls == 0
        else f"mesh, {n_hulls} open pieces by their convex hulls ({hull_share:.1%} of the mass)"
    )
    return inertia_properties(inertia / mass.sum(), com, source)


# ---------------------------------------------------------------------------------------------------------
# the motions


def quats_to_matrices(q: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) as (w, x, y, z), normalised here, to rotation matrices (..., 3, 3)."""
    q = np.asarray(q, np.float64)
    flat = q.reshape(-1, 4)[:, [1, 2, 3, 0]]
    return Rotation.from_quat(flat).as_matrix().reshape(q.shape[:-1] + (3, 3))


def euler_rates(inertia: np.ndarray, w: np.ndarray, inverse: np.ndarray | None = None) -> np.ndarray:
    """Torque-free Euler's equations: w' = J^-1 (-w x J w), body axes (with `inverse`, J^-1 given: a
    caller that steps often keeps it)."""
    if inverse is not None:
        return inverse @ -np.cross(w, inertia @ w)
    return np.linalg.solve(inertia, -np.cross(w, inertia @ w))


def _tumble_rhs(inertia: np.ndarray) -> Callable[[float, np.ndarray], np.ndarray]:
    """d/dt (w, q) of a torque-free body: Euler's equations and q' = 1/2 q (x) (0, w) (the body-frame rate
    composed on the right). Written out in floats: the integrator calls it ~10^4 times a sequence."""
    (a, b, c), (d, e, f), (g, h, k) = np.asarray(inertia, np.float64).tolist()
    (ia, ib, ic), (id_, ie, if_), (ig, ih, ik) = np.linalg.inv(inertia).tolist()

    def rhs(_t: float, y: np.ndarray) -> np.ndarray:
        w0, w1, w2, qw, qx, qy, qz = y.tolist()
        h0, h1, h2 = a * w0 + b * w1 + c * w2, d * w0 + e * w1 + f * w2, g * w0 + h * w1 + k * w2
        m0, m1, m2 = w2 * h1 - w1 * h2, w0 * h2 - w2 * h0, w1 * h0 - w0 * h1  # -w x (J w)
        return np.array(
            [
                ia * m0 + ib * m1 + ic * m2,
                id_ * m0 + ie * m1 + if_ * m2,
                ig * m0 + ih * m1 + ik * m2,
                0.5 * (-qx * w0 - qy * w1 - qz * w2),
                0.5 * (qw * w0 + qy * w2 - qz * w1),
                0.5 * (qw * w1 + qz * w0 - qx * w2),
                0.5 * (qw * w2 + qx * w1 - qy * w0),
            ]
        )

    return rhs


def _check_times(t: np.ndarray) -> np.ndarray:
    t = np.atleast_1d(np.asarray(t, np.float64))
    if t.ndim != 1 or (t.size and (t[0] < 0 or np.any(np.diff(t) < 0))):
        raise ScgenError("attitude times must be a non-decreasing 1-D array from t >= 0")
    return t


def integrate_tumble(
    inertia: np.ndarray, R0: np.ndarray, w0: np.ndarray, t: np.ndarray, rtol: float = RTOL, atol: float = ATOL
) -> tuple[np.ndarray, np.ndarray]:
    """Torque-free tumble from attitude R0 (body -> I) and body rate w0 (rad/s) at t = 0: (R_IB, w_body)
    at the non-decreasing times t ((T, 3, 3), (T, 3)), by DOP853 from 0 to t[-1].

    The steps depend on t[-1] only through the last one, so integrate a sequence over its whole span at
    once and every frame gets the same value whatever other frames are asked for.
    """
    t = _check_times(t)
    J = np.asarray(inertia, np.float64)
    q0 = Rotation.from_matrix(R0).as_quat()[[3, 0, 1, 2]]
    y0 = np.concatenate([np.asarray(w0, np.float64), q0])
    if t.size == 0:
        return np.zeros((0, 3, 3)), np.zeros((0, 3))
    if t[-1] == 0.0:
        return np.repeat(quats_to_matrices(q0)[None], t.size, 0), np.repeat(y0[None, :3], t.size, 0)
    sol = solve_ivp(_tumble_rhs(J), (0.0, float(t[-1])), y0, method="DOP853", t_eval=t, rtol=rtol, atol=atol)
    if not sol.success:
        raise ScgenError(f"tumble integration failed: {sol.message}")
    return quats_to_matrices(sol.y[3:].T), sol.y[:3].T.copy()


def spin(R0: np.ndarray, w_body: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A constant spin at body rate w_body (rad/s) from R0 (body -> I): R_IB(t) = R0 exp(t [w]x).

    The exact torque-free motion when w_body lies along a principal axis (then J w || w, w x J w = 0).
    """
    t = _check_times(t)
    w = np.asarray(w_body, np.float64)
    turns = Rotation.from_rotvec(t[:, None] * w[None]).as_matrix()
    return np.asarray(R0, np.float64) @ turns, np.repeat(w[None], t.size, 0)


@dataclass(frozen=True)
class AttitudeMotion:
    """A drawn attitude motion: `mode` (ATTITUDE_MODES), the attitude at t = 0 as a quaternion (w, x, y,
    z) body -> LVLH for 'lvlh_hold', body -> I otherwise (LVLH and I agree at t = 0), and the body rate
    at t = 0 (rad/s; spin and tumble)."""

    mode: str
    q0: tuple[float, float, float, float]
    omega0: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class AttitudeTrack:
    """The target's attitude at each time: R_IB and R_LB (T, 3, 3) and the body rate w.r.t. I (T, 3)."""

    R_ib: np.ndarray
    R_lb: np.ndarray
    omega_body: np.ndarray


def attitude_track(
    motion: AttitudeMotion, n: float, t: np.ndarray, props: MassProperties | None = None
) -> AttitudeTrack:
    """The target's attitude at times t (s) on an orbit of mean motion n (rad/s); a tumble needs `props`.

    lvlh_hold: R_LB constant, so the body turns with LVLH, w = R_LB^T (0, 0, n). inertial: R_IB constant,
    w = 0 (the target turns once an orbit in LVLH). spin and tumble: as `spin` and `integrate_tumble`.
    """
    t = _check_times(t)
    R0 = quats_to_matrices(np.asarray(motion.q0))
    R_il = lvlh_to_inertial(n, t)
    if motion.mode == "lvlh_hold":
        R_ib = R_il @ R0
        w = np.repeat((R0.T @ np.array([0.0, 0.0, n]))[None], t.size, 0)
    elif motion.mode == "inertial":
        R_ib, w = np.repeat(R0[None], t.size, 0), np.zeros((t.size, 3))
    elif motion.mode == "spin":
        R_ib, w = spin(R0, np.asarray(motion.omega0), t)
    elif motion.mode == "tumble":
        if props is None:
            raise ScgenError("a tumble needs the target's mass properties (its inertia tensor)")
        R_ib, w = integrate_tumble(props.inertia, R0, np.asarray(motion.omega0), t)
    else:
        raise ScgenError(f"unknown attitude mode {motion.mode!r}; choose one of {', '.join(ATTITUDE_MODES)}")
    return AttitudeTrack(R_ib, np.swapaxes(R_il, -1, -2) @ R_ib, w)


def draw_attitude(
    mode: str,
    rng: np.random.Generator,
    props: MassProperties | None = None,
    rate_deg: tuple[float, float] = DEFAULT_RATE_DEG,
    spin_axes: tuple[str, ...] = STABLE_SPIN_AXES,
) -> AttitudeMotion:
    """Draw an attitude motion: the initial attitude uniform over SO(3); a spin about one of `spin_axes`
    (either sense) of `props`; a tumble's rate along a direction uniform on the sphere. Rates (spin and
    tumble) are uniform over `rate_deg` (deg/s)."""
    if mode not in ATTITUDE_MODES:
        raise ScgenError(f"unknown attitude mode {mode!r}; choose one of {', '.join(ATTITUDE_MODES)}")
    lo, hi = rate_deg
    if not 0.0 <= lo <= hi:
        raise ScgenError(f"rate_deg must be an ordered range of non-negative rates, got {list(rate_deg)}")
    q0 = Rotation.from_matrix(random_rotation(rng)).as_quat()[[3, 0, 1, 2]]
    q0 = tuple(float(x) for x in q0)
    if mode in ("lvlh_hold", "inertial"):
        return AttitudeMotion(mode, q0)
    rate = math.radians(rng.uniform(lo, hi))
    if mode == "spin":
        if props is None:
            raise ScgenError("a spin needs the target's mass properties (its principal axes)")
        axis = props.axis(spin_axes[int(rng.integers(len(spin_axes)))])
        direction = axis * (1.0 if rng.uniform() < 0.5 else -1.0)
    else:
        direction = random_unit_vector(rng)
    return AttitudeMotion(mode, q0, tuple(float(x) for x in rate * direction))
