"""Relative orbital motion of a chaser about a target on a circular orbit: rendezvous sequences' physics.

Frames (every vector here is in one of them):

- **LVLH** (the Hill frame, co-moving with the target's centre of mass): x radial, outward from the
  Earth's centre (+R-bar; the Earth lies at -x), y along-track, in the direction of the orbital velocity
  (+V-bar), z along the orbital angular momentum (orbit normal; x, y, z right-handed).
- **Inertial** (I): the target's orbit-plane frame, x towards the target at t = 0, z along the orbital
  angular momentum. An Earth-centred inertial frame differs from it by one constant rotation (RAAN,
  inclination, argument of latitude at t = 0), which changes no relative quantity here. LVLH turns in it
  about z at the mean motion: its axes at time t are the columns of Rz(n t) (`lvlh_to_inertial`).

Units: metres, seconds, radians (degrees only in names that say `_deg`). For a circular orbit of radius
a the chaser's position r = (x, y, z) relative to the target obeys, to first order in |r| / a, the
Hill-Clohessy-Wiltshire (HCW) equations with mean motion n = sqrt(mu / a^3):

    x'' - 3 n^2 x - 2 n y' = f_x,    y'' + 2 n x' = f_y,    z'' + n^2 z = f_z

where f is the chaser's thrust acceleration (zero for free motion). Their closed-form solution is the
state transition matrix of `hcw_stm`; a free trajectory drifts along-track at -3 (y0' + 2 n x0) per
second (`drift_rate`) and is bounded (drift-free) exactly when y0' = -2 n x0.

The named profiles (`PROFILES`) are the chaser's initial states and, for the two forced approaches, the
thrust law they imply. The sun is fixed in I, so it turns once per orbit in LVLH; the Earth lies at
nadir (-x) with angular radius asin(R_earth / a); the eclipse test uses a cylindrical shadow.
Pure numpy: no renderer, no config; docs/sequences.md gives the equations and the drawn ranges.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np

from scgen.errors import ScgenError
from scgen.scenes.geometry import random_direction_in_cone

MU_EARTH = 3.986004418e14  # m^3/s^2, the Earth's gravitational parameter (IERS / WGS-84)
R_EARTH = 6_378_137.0  # m, the Earth's equatorial radius (WGS-84): the shadow and the Earth's disc use it
DEFAULT_ALTITUDE_KM = (
    400.0,
    800.0,
)  # low Earth orbit, where the field's rendezvous data sit (SHIRT, SISIFOS)
NADIR_LVLH = np.array([-1.0, 0.0, 0.0])  # the Earth's centre, seen from the target, in LVLH
VBAR = np.array([0.0, 1.0, 0.0])
RBAR = np.array([1.0, 0.0, 0.0])


# ---------------------------------------------------------------------------------------------------------
# the orbit


@dataclass(frozen=True)
class Orbit:
    """The target's circular orbit, set by its altitude above R_EARTH (metres)."""

    altitude_m: float

    @property
    def a(self) -> float:
        """Orbit radius (m)."""
        return R_EARTH + self.altitude_m

    @property
    def n(self) -> float:
        """Mean motion (rad/s)."""
        return mean_motion(self.a)

    @property
    def period(self) -> float:
        """Orbital period (s)."""
        return 2.0 * math.pi / self.n


def mean_motion(a: float) -> float:
    """n = sqrt(mu / a^3) (rad/s) of a circular orbit of radius a (m)."""
    if not a > R_EARTH:
        raise ScgenError(f"orbit radius must exceed the Earth's radius {R_EARTH} m, got {a}")
    return math.sqrt(MU_EARTH / a**3)


def draw_orbit(rng: np.random.Generator, altitude_km: tuple[float, float] = DEFAULT_ALTITUDE_KM) -> Orbit:
    """A circular orbit with its altitude uniform over `altitude_km`."""
    lo, hi = altitude_km
    if not 0.0 < lo <= hi:
        raise ScgenError(f"altitude_km must be an ordered range of positive altitudes, got {altitude_km}")
    return Orbit(float(rng.uniform(lo, hi)) * 1e3)


# ---------------------------------------------------------------------------------------------------------
# HCW: the closed form, the free acceleration, drift


def hcw_stm(n: float, t: np.ndarray | float) -> np.ndarray:
    """The HCW state transition matrix Phi(t) ((..., 6, 6) over t's shape): [r; v](t) = Phi(t) [r0; v0]."""
    t = np.asarray(t, dtype=np.float64)
    nt = n * t
    s, c = np.sin(nt), np.cos(nt)
    zero, one = np.zeros_like(t), np.ones_like(t)
    rows = [
        [4 - 3 * c, zero, zero, s / n, 2 * (1 - c) / n, zero],
        [6 * (s - nt), one, zero, -2 * (1 - c) / n, (4 * s - 3 * nt) / n, zero],
        [zero, zero, c, zero, zero, s / n],
        [3 * n * s, zero, zero, c, 2 * s, zero],
        [-6 * n * (1 - c), zero, zero, -2 * s, 4 * c - 3, zero],
        [zero, zero, -n * s, zero, zero, c],
    ]
    return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


def hcw_state(
    x0: np.ndarray, v0: np.ndarray, n: float, t: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """Free HCW motion from position x0 and velocity v0 (LVLH, m and m/s) at t = 0: (r, v) at times t.

    Vectorised over t: r and v have shape t.shape + (3,).
    """
    state0 = np.concatenate([np.asarray(x0, np.float64), np.asarray(v0, np.float64)])
    state = hcw_stm(n, t) @ state0
    return state[..., :3], state[..., 3:]


def hcw_acceleration(r: np.ndarray, v: np.ndarray, n: float) -> np.ndarray:
    """The free-motion acceleration of the HCW equations at (r, v): (3 n^2 x + 2 n y', -2 n x', -n^2 z)."""
    r, v = np.asarray(r, np.float64), np.asarray(v, np.float64)
    return np.stack(
        [3 * n * n * r[..., 0] + 2 * n * v[..., 1], -2 * n * v[..., 0], -n * n * r[..., 2]], axis=-1
    )


def hcw_thrust(r: np.ndarray, v: np.ndarray, accel: np.ndarray, n: float) -> np.ndarray:
    """The thrust acceleration f a trajectory needs to have acceleration `accel` at (r, v): f = r'' - free."""
    return np.asarray(accel, np.float64) - hcw_acceleration(r, v, n)


def drift_rate(x0: np.ndarray, v0: np.ndarray, n: float) -> float:
    """The secular along-track velocity of free motion from (x0, v0): -3 (y0' + 2 n x0) (m/s).

    Equal to -(3/2) n x_c with x_c = 4 x0 + 2 y0' / n the mean radial offset: a chaser below the target
    (x_c < 0) moves ahead of it; zero exactly on the bounded-motion condition y0' = -2 n x0.
    """
    return -3.0 * (float(v0[1]) + 2.0 * n * float(x0[0]))


def hill_state(
    n: float,
    centre_x: float = 0.0,
    centre_y: float = 0.0,
    radial: float = 0.0,
    cross: float = 0.0,
    phase: float = 0.0,
    cross_phase: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The state at t = 0 of the general free HCW motion, written by its geometry (m, rad):

        x = x_c + A cos(nt + phase),   y = y_c - (3/2) n x_c t - 2 A sin(nt + phase),
        z = B sin(nt + cross_phase)

    with x_c = centre_x, y_c = centre_y, A = radial, B = cross: a 2:1 ellipse in the orbit plane whose
    centre drifts along-track at -(3/2) n x_c, and an independent cross-track oscillation.
    """
    th, tz = phase, cross_phase
    r0 = np.array(
        [centre_x + radial * math.cos(th), centre_y - 2 * radial * math.sin(th), cross * math.sin(tz)]
    )
    v0 = np.array(
        [
            -n * radial * math.sin(th),
            -1.5 * n * centre_x - 2 * n * radial * math.cos(th),
            n * cross * math.cos(tz),
        ]
    )
    return r0, v0


# ---------------------------------------------------------------------------------------------------------
# the chaser's profiles


class Profile(Protocol):
    """A chaser's relative motion: the state at times t (LVLH) and the thrust it needs (0 for free)."""

    name: ClassVar[str]
    forced: ClassVar[bool]

    def state(self, n: float, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]: ...

    def thrust(self, n: float, t: np.ndarray | float) -> np.ndarray: ...


class _Free:
    """Free HCW motion from `initial_state`: no thrust."""

    forced: ClassVar[bool] = False

    def initial_state(self, n: float) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def state(self, n: float, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """(r, v) at times t (m, m/s), by the closed form."""
        return hcw_state(*self.initial_state(n), n, t)

    def thrust(self, n: float, t: np.ndarray | float) -> np.ndarray:
        """Zero: free motion."""
        return np.zeros(np.shape(t) + (3,))


@dataclass(frozen=True)
class VBarHold(_Free):
    """Station keeping on V-bar at along-track offset `y_m` (negative: behind the target).

    r = (0, y, 0), v = 0 is an equilibrium of the HCW equations (every term vanishes): free motion,
    no thrust. (Real holds fight drag and perturbations; HCW has none.)
    """

    name: ClassVar[str] = "vbar_hold"
    y_m: float

    def initial_state(self, n: float) -> tuple[np.ndarray, np.ndarray]:
        return np.array([0.0, self.y_m, 0.0]), np.zeros(3)


@dataclass(frozen=True)
class SafetyEllipse(_Free):
    """A passive safety ellipse: drift-free free motion about a point of V-bar (`hill_state` with x_c = 0).

    Radial amplitude A = `radial_m`, along-track 2 A about `centre_m`, cross-track B = `cross_m`, in
    phase with the along-track motion (z = B sin(nt + phase) while x = A cos(nt + phase)), so x and z
    never vanish together and the chaser never crosses V-bar: it stays safe if its along-track position
    is uncertain. Bounded: y0' = -2 n x0 holds, so it closes after every orbit.
    """

    name: ClassVar[str] = "safety_ellipse"
    radial_m: float
    cross_m: float
    centre_m: float
    phase_rad: float

    def initial_state(self, n: float) -> tuple[np.ndarray, np.ndarray]:
        return hill_state(n, 0.0, self.centre_m, self.radial_m, self.cross_m, self.phase_rad, self.phase_rad)


@dataclass(frozen=True)
class FlyBy(_Free):
    """A drifting fly-by: free motion on a lower or higher orbit, passing the target along V-bar.

    The chaser's mean radial offset x_c = `offset_m` makes it drift along-track at -(3/2) n x_c (below
    the target, x_c < 0, it overtakes it); it starts at along-track `start_m` on the side it drifts from,
    with an in-plane oscillation of radial amplitude `radial_m` (< |x_c| as drawn, so it never crosses
    the target's orbit) and a cross-track one of amplitude `cross_m`.
    """

    name: ClassVar[str] = "flyby"
    offset_m: float
    start_m: float
    radial_m: float
    cross_m: float
    phase_rad: float
    cross_phase_rad: float

    def initial_state(self, n: float) -> tuple[np.ndarray, np.ndarray]:
        return hill_state(
            n, self.offset_m, self.start_m, self.radial_m, self.cross_m, self.phase_rad, self.cross_phase_rad
        )


def straight_line(
    direction: np.ndarray, start_m: float, speed_mps: float, stop_m: float, t: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """A straight-line approach towards the target along -`direction` (unit, LVLH): range
    max(start - speed t, stop) from the target on the `direction` side, then held at `stop_m`."""
    t = np.asarray(t, np.float64)
    range_m = np.maximum(start_m - speed_mps * t, stop_m)
    moving = start_m - speed_mps * t > stop_m
    d = np.asarray(direction, np.float64)
    return range_m[..., None] * d, np.where(moving, -speed_mps, 0.0)[..., None] * d


@dataclass(frozen=True)
class _Forced:
    """A forced straight-line approach at constant closing speed, then a forced hold at `stop_m`.

    Not free HCW motion: r'' = 0 along the line, so the thrusters supply f = -(3 n^2 x + 2 n y', -2 n x',
    -n^2 z) (`hcw_thrust`), continuously, plus an impulse of `closing_mps` against the motion on reaching
    the hold point (and the one that set the closing speed before t = 0). The hold off V-bar is forced too.
    """

    forced: ClassVar[bool] = True

    def line(self) -> tuple[np.ndarray, float, float, float]:
        raise NotImplementedError

    def state(self, n: float, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """(r, v) at times t (m, m/s); n does not enter (the motion is imposed)."""
        return straight_line(*self.line(), t)

    def thrust(self, n: float, t: np.ndarray | float) -> np.ndarray:
        """The continuous thrust acceleration (m/s^2) that keeps the chaser on the line (no impulses)."""
        r, v = self.state(n, t)
        return hcw_thrust(r, v, np.zeros_like(r), n)


@dataclass(frozen=True)
class RBarApproach(_Forced):
    """An R-bar approach: straight along the radial axis at constant closing speed, forced.

    `side` +1 comes down from above the target (the Earth behind it in the view), -1 up from below
    (space behind, as the Shuttle came to the ISS). A straight line on R-bar is not free motion: a chaser
    at rest on R-bar drifts along V-bar at -6 n x0, so the line takes the thrust f = (-3 n^2 x, 2 n x', 0).
    """

    name: ClassVar[str] = "rbar_approach"
    side: int
    start_m: float
    closing_mps: float
    stop_m: float

    def line(self) -> tuple[np.ndarray, float, float, float]:
        return self.side * RBAR, self.start_m, self.closing_mps, self.stop_m


@dataclass(frozen=True)
class CorridorApproach(_Forced):
    """A straight-line approach inside a corridor: along a fixed unit `direction` (LVLH, from the
    target to the chaser) drawn within a cone about the approach axis (-V-bar by default), forced."""

    name: ClassVar[str] = "corridor_approach"
    direction: tuple[float, float, float]
    start_m: float
    closing_mps: float
    stop_m: float

    def line(self) -> tuple[np.ndarray, float, float, float]:
        return np.asarray(self.direction), self.start_m, self.closing_mps, self.stop_m


# Each profile's drawn ranges (uniform over each): metres of the real spacecraft, m/s, degrees. HCW is
# linear, so a trajectory scaled by k (positions and velocities) is the trajectory of the scaled initial
# state: a renderer scales them by the model's diameter over the spacecraft's, times unchanged.
DEFAULT_PROFILE_RANGES: dict[str, dict[str, Any]] = {
    "vbar_hold": {"distance_m": (20.0, 100.0), "behind_prob": 0.5},
    "rbar_approach": {
        "start_m": (30.0, 100.0),
        "closing_mps": (0.02, 0.1),
        "stop_m": (5.0, 15.0),
        "above_prob": 0.5,
    },
    "corridor_approach": {
        "axis": (0.0, -1.0, 0.0),  # -V-bar: from behind, the usual docking approach
        "half_angle_deg": 10.0,
        "start_m": (30.0, 150.0),
        "closing_mps": (0.02, 0.2),
        "stop_m": (5.0, 15.0),
    },
    "safety_ellipse": {"radial_m": (10.0, 50.0), "cross_m": (10.0, 50.0), "centre_m": (-10.0, 10.0)},
    "flyby": {
        "offset_m": (5.0, 30.0),  # |x_c|, the sign drawn: below (ahead-drifting) or above
        "start_m": (50.0, 150.0),  # |y0|, on the side the chaser drifts from
        "radial_frac": (0.0, 0.5),  # A / |x_c|: < 1, the chaser never crosses the target's orbit
        "cross_m": (0.0, 20.0),
    },
}
PROFILES: dict[str, type] = {
    p.name: p for p in (VBarHold, RBarApproach, CorridorApproach, SafetyEllipse, FlyBy)
}


def _uniform(rng: np.random.Generator, key: str, lohi: tuple[float, float]) -> float:
    lo, hi = lohi
    if not lo <= hi:
        raise ScgenError(f"{key} must be an ordered range [lo, hi], got {list(lohi)}")
    return float(rng.uniform(lo, hi))


def draw_profile(name: str, rng: np.random.Generator, ranges: dict[str, Any] | None = None) -> Profile:
    """Draw profile `name`'s parameters from its ranges (DEFAULT_PROFILE_RANGES, updated by `ranges`)."""
    if name not in PROFILES:
        raise ScgenError(f"unknown relative-motion profile {name!r}; choose one of {', '.join(PROFILES)}")
    unknown = sorted(set(ranges or {}) - set(DEFAULT_PROFILE_RANGES[name]))
    if unknown:
        raise ScgenError(
            f"unknown {name} key(s) {', '.join(unknown)}; known: {', '.join(DEFAULT_PROFILE_RANGES[name])}"
        )
    r = {**DEFAULT_PROFILE_RANGES[name], **(ranges or {})}

    def u(key: str) -> float:
        return _uniform(rng, f"{name}.{key}", r[key])

    if name == "vbar_hold":
        distance = u("distance_m")
        return VBarHold(-distance if rng.uniform() < r["behind_prob"] else distance)
    if name in ("rbar_approach", "corridor_approach"):
        start, closing, stop = u("start_m"), u("closing_mps"), u("stop_m")
        if not 0.0 < stop <= start or not closing > 0.0:
            raise ScgenError(f"{name}: need 0 < stop_m <= start_m and closing_mps > 0")
        if name == "rbar_approach":
            return RBarApproach(1 if rng.uniform() < r["above_prob"] else -1, start, closing, stop)
        axis = np.asarray(r["axis"], np.float64)
        d = random_direction_in_cone(rng, axis / np.linalg.norm(axis), math.radians(r["half_angle_deg"]))
        return CorridorApproach(tuple(float(x) for x in d), start, closing, stop)
    phase = float(rng.uniform(0.0, 2.0 * math.pi))
    if name == "safety_ellipse":
        return SafetyEllipse(u("radial_m"), u("cross_m"), u("centre_m"), phase)
    offset = u("offset_m") * (1.0 if rng.uniform() < 0.5 else -1.0)
    start = u("start_m") * math.copysign(1.0, offset)  # x_c < 0 drifts towards +y: start behind (y < 0)
    if not 0.0 <= r["radial_frac"][0] <= r["radial_frac"][1] < 1.0:
        raise ScgenError(f"flyby.radial_frac must be a range within [0, 1), got {list(r['radial_frac'])}")
    radial = u("radial_frac") * abs(offset)
    return FlyBy(offset, start, radial, u("cross_m"), phase, float(rng.uniform(0.0, 2.0 * math.pi)))


# ---------------------------------------------------------------------------------------------------------
# the sun and the Earth


@dataclass(frozen=True)
class Sun:
    """The sun's direction, fixed in the inertial frame I: elevation `beta_rad` over the orbit plane (the
    beta angle) and azimuth `azimuth_rad` in it, from the target's position at t = 0."""

    beta_rad: float
    azimuth_rad: float

    def inertial(self) -> np.ndarray:
        """Unit vector towards the sun in I."""
        cb = math.cos(self.beta_rad)
        return np.array(
            [cb * math.cos(self.azimuth_rad), cb * math.sin(self.azimuth_rad), math.sin(self.beta_rad)]
        )


def draw_sun(rng: np.random.Generator, max_beta_deg: float = 90.0) -> Sun:
    """A sun direction uniform over the sphere's band |beta| <= max_beta_deg (uniform in sin beta)."""
    s = math.sin(math.radians(max_beta_deg))
    return Sun(math.asin(rng.uniform(-s, s)), float(rng.uniform(0.0, 2.0 * math.pi)))


def lvlh_to_inertial(n: float, t: np.ndarray | float) -> np.ndarray:
    """Rotation LVLH -> I at times t ((..., 3, 3)): Rz(n t), its columns the LVLH axes in I."""
    t = np.asarray(t, np.float64)
    c, s = np.cos(n * t), np.sin(n * t)
    zero, one = np.zeros_like(t), np.ones_like(t)
    return np.stack(
        [np.stack([c, -s, zero], -1), np.stack([s, c, zero], -1), np.stack([zero, zero, one], -1)], -2
    )


def sun_direction_lvlh(sun: Sun, n: float, t: np.ndarray | float) -> np.ndarray:
    """Unit vector towards the sun in LVLH at times t: fixed in I, it turns about z at -n, once an orbit."""
    return np.einsum("...ji,j->...i", lvlh_to_inertial(n, t), sun.inertial())


def earth_angular_radius(a: float) -> float:
    """Angular radius (rad) of the Earth's disc seen from orbit radius a: asin(R_EARTH / a); it lies at
    nadir (NADIR_LVLH). From a chaser |r| away the centre direction moves by < |r| / a (~1e-5 rad)."""
    return math.asin(R_EARTH / a)


def in_eclipse(sun_lvlh: np.ndarray, a: float, r: np.ndarray | None = None) -> np.ndarray:
    """Whether a point at LVLH offset r (default: the target) is in the Earth's shadow.

    Cylindrical shadow: the point is eclipsed when the sun is behind the Earth (the point's position p
    from the Earth's centre has p . s < 0) and p lies within R_EARTH of the Earth-sun line. The true umbra
    is a cone narrowing at (R_sun - R_earth) / 1 AU = 0.26 deg, so at LEO it is up to ~30 km narrower than
    the cylinder (and the penumbra as much wider): entry and exit move by ~10 s at beta 0, more at
    grazing beta. Shape: that of s and r broadcast, less the last axis.
    """
    s = np.asarray(sun_lvlh, np.float64)
    p = np.array([a, 0.0, 0.0]) + (0.0 if r is None else np.asarray(r, np.float64))
    along = np.sum(p * s, axis=-1)
    perp2 = np.sum(p * p, axis=-1) - along**2
    return (along < 0.0) & (perp2 < R_EARTH**2)
