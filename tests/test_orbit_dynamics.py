"""The physics of rendezvous sequences (scgen.scenes.motion.orbit, scgen.scenes.motion.tumble), checked
against the equations they solve: HCW relative motion, the profiles' defining properties, the sun and the
Earth's shadow, and torque-free attitude dynamics (conservation laws, the stability of principal-axis
spins).
No renderer; the whole file runs in a few seconds."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from scipy.integrate import solve_ivp

from scgen.errors import ScgenError
from scgen.scenes.model import load_target
from scgen.scenes.motion.orbit import (
    PROFILES,
    R_EARTH,
    FlyBy,
    Orbit,
    SafetyEllipse,
    Sun,
    draw_orbit,
    draw_profile,
    drift_rate,
    earth_angular_radius,
    hcw_acceleration,
    hcw_state,
    in_eclipse,
    lvlh_to_inertial,
    sun_direction_lvlh,
)
from scgen.scenes.motion.tumble import (
    ATTITUDE_MODES,
    AttitudeMotion,
    attitude_track,
    draw_attitude,
    integrate_tumble,
    mass_properties,
    spin,
)

pytestmark = pytest.mark.numeric  # rounding-level bounds: rerun under a second kernel set (make test)

ORBIT = Orbit(500e3)  # n = 1.107e-3 rad/s, period 94.6 min
N = ORBIT.n
EPS = np.finfo(np.float64).eps  # 2.2e-16


def random_states(seed: int, k: int = 4) -> list[tuple[np.ndarray, np.ndarray]]:
    """k initial states of rendezvous size: positions up to ~100 m, velocities up to ~0.1 m/s."""
    rng = np.random.default_rng(seed)
    return [(rng.uniform(-100, 100, 3), rng.uniform(-0.1, 0.1, 3)) for _ in range(k)]


# ---------------------------------------------------------------------------------------------------------
# HCW


def test_orbit_constants_give_the_known_low_orbit():
    # a 500 km circular orbit has a period of 94.6 min; the Earth's disc from there is 68.0 deg in radius
    # (the tolerances: the rounding of the quoted figures)
    assert ORBIT.period / 60 == pytest.approx(94.62, abs=0.01)
    assert math.degrees(earth_angular_radius(ORBIT.a)) == pytest.approx(68.0, abs=0.05)
    alt = [draw_orbit(np.random.default_rng(s)).altitude_m for s in range(50)]
    assert min(alt) >= 400e3 and max(alt) <= 800e3


def test_hcw_closed_form_satisfies_the_hcw_equations():
    """The residual of the ODEs, with r'' from central differences of the closed form's positions."""
    h = 1.0  # s
    t = np.arange(0.0, 2 * ORBIT.period, 7.0)
    for x0, v0 in random_states(0):
        r_m, _ = hcw_state(x0, v0, N, t - h)
        r, v = hcw_state(x0, v0, N, t)
        r_p, _ = hcw_state(x0, v0, N, t + h)
        accel_fd = (r_p - 2 * r + r_m) / h**2
        v_fd = (r_p - r_m) / (2 * h)
        free = hcw_acceleration(r, v, N)
        # the ODE's terms are ~ n^2 |r| ~ 1e-4 m/s^2; central differences err by ~ (n h)^2 / 12 ~ 1e-7 of
        # them (and rounding by ~ eps |r| / h^2 ~ 1e-14 m/s^2): 1e-5 of the terms leaves a 100x margin
        scale = np.abs(free).max()
        assert np.abs(accel_fd - free).max() < 1e-5 * scale
        assert np.abs(v_fd - v).max() < 1e-5 * np.abs(v).max()  # the closed form's v is r's derivative


def test_hcw_closed_form_equals_numerical_integration():
    t = np.linspace(0.0, 3 * ORBIT.period, 200)
    for x0, v0 in random_states(1):
        sol = solve_ivp(
            lambda _t, y: np.concatenate([y[3:], hcw_acceleration(y[:3], y[3:], N)]),
            (0.0, t[-1]),
            np.concatenate([x0, v0]),
            method="DOP853",
            t_eval=t,
            rtol=1e-12,
            atol=1e-10,
        )
        r, v = hcw_state(x0, v0, N, t)
        # DOP853 at rtol 1e-12 over 3 orbits keeps ~1e-10 relative; 1e-8 of the motion's size leaves margin
        assert np.abs(sol.y[:3].T - r).max() < 1e-8 * np.abs(r).max()
        assert np.abs(sol.y[3:].T - v).max() < 1e-8 * np.abs(v).max()


def test_hcw_is_linear_so_a_trajectory_scales_with_the_model():
    t = np.linspace(0.0, ORBIT.period, 50)
    x0, v0 = random_states(2, 1)[0]
    r, v = hcw_state(x0, v0, N, t)
    r_k, v_k = hcw_state(0.002 * x0, 0.002 * v0, N, t)  # e.g. a 100 m spacecraft rendered as a 0.2 m model
    # the same float operations on scaled inputs: equal to a few roundings (eps = 2.2e-16), 1e-12 is 4500 eps
    np.testing.assert_allclose(r_k, 0.002 * r, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(v_k, 0.002 * v, rtol=1e-12, atol=1e-15)


# ---------------------------------------------------------------------------------------------------------
# the profiles


def test_a_vbar_hold_stays_put_and_an_rbar_point_does_not():
    t = np.linspace(0.0, 5 * ORBIT.period, 400)
    for seed in range(5):
        hold = draw_profile("vbar_hold", np.random.default_rng(seed))
        r, v = hold.state(N, t)
        assert r[0, 0] == 0 and r[0, 2] == 0 and 20 <= abs(r[0, 1]) <= 100
        # on V-bar at rest every HCW term vanishes: the state transition keeps it to rounding
        assert np.abs(r - r[0]).max() < 1e-9 * abs(r[0, 1]) and np.abs(v).max() < 1e-12
        assert not hold.thrust(N, t).any()
    # the same distance on R-bar at rest is no equilibrium: it drifts by 6 n x0 * t (12 pi x0 an orbit)
    r, _ = hcw_state(np.array([50.0, 0, 0]), np.zeros(3), N, ORBIT.period)
    assert r[1] == pytest.approx(-12 * math.pi * 50.0, rel=1e-9)  # sin/cos of n t ~ 2 pi: ~10 eps each


def test_a_safety_ellipse_closes_after_an_orbit_never_drifts_and_never_crosses_vbar():
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 10 * ORBIT.period, 4001)
    for _ in range(10):
        ellipse = draw_profile("safety_ellipse", rng)
        assert isinstance(ellipse, SafetyEllipse)
        x0, v0 = ellipse.initial_state(N)
        assert v0[1] == pytest.approx(-2 * N * x0[0], abs=1e-15)  # the bounded-motion condition
        assert drift_rate(x0, v0, N) == pytest.approx(0.0, abs=1e-15)
        r, v = ellipse.state(N, t)
        size = ellipse.radial_m
        # after each of 10 orbits the state returns to the start (to rounding, ~1e-12 of the size)
        ends = np.flatnonzero(np.isclose(t % ORBIT.period, 0) | np.isclose(t % ORBIT.period, ORBIT.period))
        assert len(ends) == 11
        assert np.abs(r[ends] - x0).max() < 1e-9 * size and np.abs(v[ends] - v0).max() < 1e-9 * N * size
        # it stays inside its 2:1 box: |x| <= A, |y - centre| <= 2A, |z| <= B
        assert np.abs(r[:, 0]).max() <= size * (1 + 1e-9)
        assert np.abs(r[:, 1] - ellipse.centre_m).max() <= 2 * size * (1 + 1e-9)
        assert np.abs(r[:, 2]).max() <= ellipse.cross_m * (1 + 1e-9)
        # passive safety: x = A cos, z = B sin never vanish together, so |(x, z)| >= min(A, B) everywhere
        assert np.hypot(r[:, 0], r[:, 2]).min() >= min(size, ellipse.cross_m) * (1 - 1e-9)


def test_a_flyby_drifts_at_the_rate_the_theory_gives_and_passes_the_target():
    rng = np.random.default_rng(4)
    for _ in range(10):
        flyby = draw_profile("flyby", rng)
        assert isinstance(flyby, FlyBy)
        x0, v0 = flyby.initial_state(N)
        rate = drift_rate(x0, v0, N)  # -3 (y0' + 2 n x0), from the initial state alone
        assert rate == pytest.approx(-1.5 * N * flyby.offset_m, rel=1e-12)  # = -(3/2) n x_c
        assert abs(rate) > 0
        # over whole orbits the periodic part returns: the along-track advance is the secular drift
        for k in (1, 3):
            r, v = flyby.state(N, np.array([0.0, k * ORBIT.period]))
            assert r[1, 1] - r[0, 1] == pytest.approx(rate * k * ORBIT.period, rel=1e-9)
            assert np.abs(r[1] - r[0] - np.array([0, rate * k * ORBIT.period, 0])).max() < 1e-9 * abs(r[0, 1])
        # the chaser drifts towards the target and past it, never crossing the target's orbit (x != 0)
        t = np.linspace(0.0, 2 * abs(flyby.start_m / rate), 2000)
        r, _ = flyby.state(N, t)
        assert np.sign(r[0, 1]) != np.sign(r[-1, 1])
        assert np.all(np.sign(r[:, 0]) == np.sign(flyby.offset_m))


@pytest.mark.parametrize("name", ["rbar_approach", "corridor_approach"])
def test_a_forced_approach_closes_at_its_speed_and_its_thrust_closes_the_hcw_equations(name):
    rng = np.random.default_rng(5)
    for _ in range(5):
        approach = draw_profile(name, rng)
        assert approach.forced
        direction, start, speed, stop = approach.line()
        if name == "rbar_approach":
            assert abs(direction[0]) == 1
        else:  # inside the 10 deg corridor about -V-bar
            assert math.degrees(math.acos(-direction[1])) <= 10 + 1e-9
        t_stop = (start - stop) / speed
        t = np.linspace(0.0, 1.5 * t_stop, 3001)
        r, v = approach.state(N, t)
        rng_m = np.linalg.norm(r, axis=1)
        # a straight line towards the target at the closing speed, then held at the stop range (to rounding:
        # a unit vector and a range of ~100 m good to a few eps relative; 1e-12 is ~5000 eps)
        np.testing.assert_allclose(r / rng_m[:, None], np.broadcast_to(direction, r.shape), atol=1e-12)
        np.testing.assert_allclose(rng_m, np.maximum(start - speed * t, stop), rtol=1e-12)
        # thrust + the free HCW acceleration = the motion's own acceleration (finite differences), away
        # from the hold point's braking impulse; at ~1e-3 m/s^2 scale the differences are exact to rounding
        h = 1.0
        away = np.abs(t - t_stop) > 2 * h
        r_m, _ = approach.state(N, t - h)
        r_p, _ = approach.state(N, t + h)
        accel_fd = (r_p - 2 * r + r_m) / h**2
        total = approach.thrust(N, t) + hcw_acceleration(r, v, N)
        scale = np.abs(hcw_acceleration(r, v, N)).max()
        assert np.abs(accel_fd[away] - total[away]).max() < 1e-6 * scale
        assert np.abs(approach.thrust(N, t)).max() > 0  # not free motion


def test_profiles_are_drawn_reproducibly_and_bad_names_are_refused():
    for name in PROFILES:
        assert draw_profile(name, np.random.default_rng(9)) == draw_profile(name, np.random.default_rng(9))
    with pytest.raises(ScgenError, match="unknown relative-motion profile"):
        draw_profile("hohmann", np.random.default_rng(0))
    with pytest.raises(ScgenError, match="ordered range"):
        draw_profile("safety_ellipse", np.random.default_rng(0), {"radial_m": (5.0, 1.0)})
    with pytest.raises(ScgenError, match="unknown flyby key"):
        draw_profile("flyby", np.random.default_rng(0), {"offset": (5.0, 10.0)})


# ---------------------------------------------------------------------------------------------------------
# the sun, the Earth, the eclipse


def test_the_sun_is_fixed_in_inertial_space_and_turns_once_an_orbit_in_lvlh():
    sun = Sun(math.radians(30.0), math.radians(40.0))
    t = np.linspace(0.0, ORBIT.period, 1001)
    s = sun_direction_lvlh(sun, N, t)
    # unit vectors through two 3x3 rotations: a few eps (2.2e-16) per component, so 1e-14 is ~50 eps; the
    # unwrapped azimuth sums 1000 steps' roundings (~1e-13), 1e-9 bounds it with margin
    np.testing.assert_allclose(
        np.einsum("tij,tj->ti", lvlh_to_inertial(N, t), s), np.tile(sun.inertial(), (1001, 1)), atol=1e-14
    )
    np.testing.assert_allclose(s[:, 2], math.sin(sun.beta_rad), atol=1e-14)  # the beta angle stays
    azimuth = np.unwrap(np.arctan2(s[:, 1], s[:, 0]))
    assert azimuth[-1] - azimuth[0] == pytest.approx(-2 * math.pi, abs=1e-9)  # one turn, retrograde
    assert np.all(np.diff(azimuth) < 0)
    np.testing.assert_allclose(s[-1], s[0], atol=1e-12)


def test_the_eclipse_flag_is_true_exactly_when_the_sun_is_behind_the_earth():
    t = np.linspace(0.0, ORBIT.period, 100_001)[:-1]
    # the cylinder's edge: the sun within asin(R / a) of the nadir (the same angle as the Earth's radius
    # seen from orbit), where the target's distance from the Earth-sun line a sin(angle) is below R
    half = earth_angular_radius(ORBIT.a)
    s = sun_direction_lvlh(Sun(0.0, 0.0), N, t)  # beta 0: the sun sweeps through nadir once an orbit
    ecl = in_eclipse(s, ORBIT.a)
    from_nadir = np.arccos(np.clip(-s[:, 0], -1, 1))  # angle of the sun from straight below the target
    assert ecl[from_nadir < half - 1e-9].all() and not ecl[from_nadir > half + 1e-9].any()
    assert ecl.mean() == pytest.approx(half / math.pi, abs=2e-5)  # 37.8 % of the orbit; grid step 1e-5
    assert not in_eclipse(np.array([1.0, 0, 0]), ORBIT.a)  # local noon: the sun overhead
    assert in_eclipse(np.array([-1.0, 0, 0]), ORBIT.a)  # local midnight: the sun straight behind the Earth
    assert not in_eclipse(np.array([0.0, 1.0, 0]), ORBIT.a)  # dawn/dusk: the sun on the horizon plane
    # the closest the target comes to the Earth-sun line is a sin(beta): above asin(R / a) no eclipse
    assert not in_eclipse(sun_direction_lvlh(Sun(half + 1e-3, 1.0), N, t), ORBIT.a).any()
    assert in_eclipse(sun_direction_lvlh(Sun(half - 1e-2, 1.0), N, t), ORBIT.a).any()
    # the chaser 100 m off the target shares its shadow but at the edge (a 100 m shift of the cylinder)
    r = np.array([0.0, 100.0, 0.0])
    assert (in_eclipse(s, ORBIT.a, r) != ecl).mean() < 1e-3
    assert math.degrees(half) == pytest.approx(68.0, abs=0.05) and R_EARTH / ORBIT.a == pytest.approx(
        math.sin(half)
    )


# ---------------------------------------------------------------------------------------------------------
# attitude


@pytest.fixture(scope="module")
def props():
    """The bundled spacecraft's mass properties (uniform density)."""
    return mass_properties([mesh for _, mesh in load_target().parts])


def test_inertia_of_a_mesh_is_the_solids_and_an_open_mesh_says_it_used_its_hull(props):
    # a solid box a x b x c: J / m = diag(b^2 + c^2, a^2 + c^2, a^2 + b^2) / 12 about its centre; the
    # mesh integrals sum 12 triangles' O(1) terms, exact to ~100 eps (2e-14): 1e-12 below leaves margin, and
    # the major axis from eigh is good to eps |J| / gap (gap 3/12 of |J| = 13/12: ~1e-15)
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    box.apply_translation([0.3, -0.2, 0.1])
    mp = mass_properties(box)
    np.testing.assert_allclose(mp.inertia, np.diag([13.0, 10.0, 5.0]) / 12, atol=1e-12)
    np.testing.assert_allclose(mp.centre_of_mass, [0.3, -0.2, 0.1], atol=1e-12)
    assert mp.source == "mesh"
    np.testing.assert_allclose(np.abs(mp.axis("major")), [1, 0, 0], atol=1e-12)
    # inside out, it is the same solid; split into two disjoint parts, the parallel-axis sum is the whole
    inverted = box.copy()
    inverted.invert()
    np.testing.assert_allclose(mass_properties(inverted).inertia, mp.inertia, atol=1e-12)
    halves = [trimesh.creation.box(extents=(1.0, 2.0, 1.5)) for _ in range(2)]
    halves[0].apply_translation([0.3, -0.2, 0.1 - 0.75])
    halves[1].apply_translation([0.3, -0.2, 0.1 + 0.75])
    np.testing.assert_allclose(mass_properties(halves).inertia, mp.inertia, atol=1e-12)
    # a box without its lid is open: its convex hull (the closed box) stands in, and the source says so
    lidless = trimesh.Trimesh(box.vertices, box.faces[:-2])
    assert not lidless.is_watertight
    open_mp = mass_properties(lidless)
    np.testing.assert_allclose(open_mp.inertia, mp.inertia, atol=1e-12)
    assert "convex hull" in open_mp.source and "100.0% of the mass" in open_mp.source
    with pytest.raises(ScgenError, match="encloses no volume"):
        mass_properties(trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]))
    # the bundled model: closed parts but for a few open ones (antenna dishes), a small share of its mass
    assert props.source.startswith("mesh") and "open pieces" in props.source
    assert np.all(np.diff(props.principal_moments) > 0.05 * props.principal_moments[0])  # 3 distinct
    # eigh's vectors are orthonormal to a few eps (|Q^T Q - I| <= p(n) eps), approx's default 1e-6 wider still
    np.testing.assert_allclose(props.principal_axes.T @ props.principal_axes, np.eye(3), atol=1e-12)
    assert np.linalg.det(props.principal_axes) == pytest.approx(1.0)


def test_a_torque_free_tumble_conserves_inertial_angular_momentum_and_energy(props):
    rng = np.random.default_rng(6)
    t = np.linspace(0.0, 1200.0, 241)  # 20 min at 5 s a frame
    J = props.inertia
    for _ in range(3):
        motion = draw_attitude("tumble", rng, props, rate_deg=(3.0, 5.0))
        track = attitude_track(motion, N, t, props)
        w = track.omega_body
        # w[0] is the integration's start, omega0 itself (DOP853's dense output at a step's start is its
        # y_old); x (180 / pi) and (x 180) / pi: two roundings a side, 4 u64 at most; rad for deg is 57x
        assert math.degrees(np.linalg.norm(w[0])) == pytest.approx(
            np.linalg.norm(motion.omega0) * 180 / math.pi, rel=1e-15
        )
        H = np.einsum("tij,jk,tk->ti", track.R_ib, J, w)  # angular momentum in I: R_IB J w
        T = 0.5 * np.einsum("ti,ij,tj->t", w, J, w)
        # DOP853 at rtol 1e-10 keeps ~1e-10 relative per unit time scale; over ~100 rad of rotation the
        # drift stays below 1e-8. A quaternion-kinematics sign error would turn H by radians, not 1e-8.
        assert np.abs(H - H[0]).max() < 1e-8 * np.linalg.norm(H[0])
        assert np.abs(T - T[0]).max() < 1e-8 * T[0]
        # ... while the body rate itself moves: it is a tumble, not a spin
        assert np.abs(w - w[0]).max() > 1e-3 * np.linalg.norm(w[0])
        # rotation matrices from normalised quaternions: orthonormal to a few eps (2.2e-16) per entry
        np.testing.assert_allclose(
            np.einsum("tji,tjk->tik", track.R_ib, track.R_ib),
            np.broadcast_to(np.eye(3), (241, 3, 3)),
            atol=1e-12,
        )


def angle_from(w: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Angle (rad) between each body rate and the unit axis, either sense. atan2 of the cross and dot
    products is good to a few eps at every angle; arccos of the cosine is not near 0, where a cosine one
    ulp below 1 reads as arccos(1 - eps) = sqrt(2 eps) = 2.1e-8 rad."""
    return np.arctan2(np.linalg.norm(np.cross(w, axis), axis=-1), np.abs(w @ axis))


@pytest.mark.parametrize("which", ["minor", "major", "intermediate"])
def test_a_spin_about_the_major_or_minor_axis_stays_a_spin_and_about_the_intermediate_one_flips(props, which):
    """Dzhanibekov, with the bundled model's moments I1 : I2 : I3 = 1 : 1.11 : 1.28. About the intermediate
    axis a wobble grows as exp(l t), l = w sqrt((I2 - I1)(I3 - I2) / (I1 I3)) = 0.12 w (~95 s at 5 deg/s):
    from 1e-3 rad the rate turns over to the axis' other sense after ~830 s, inside the 3000 s run. About
    the minor and major axes the rate's path (the polhode) is a small ellipse about the axis, semi-axes in
    ratio sqrt(I3 (I3 - I1) / (I2 (I2 - I1))) = 1.7 and sqrt(I1 (I3 - I1) / (I2 (I3 - I2))) = 1.2: the tilt
    stays below 1.7 times the start's, so 5 times bounds it with margin while a flip is ~1000 times."""
    axis = props.axis(which)
    rate = math.radians(5.0)
    tilt = 1e-3  # rad: the start's deviation from the axis
    u, _ = np.linalg.qr(np.column_stack([axis, [0.3, 0.5, 0.8]]))  # u[:, 1]: a unit vector normal to axis
    w0 = rate * (math.cos(tilt) * axis + math.sin(tilt) * u[:, 1])
    t = np.linspace(0.0, 3000.0, 601)
    R0 = np.eye(3)
    R_ib, w = integrate_tumble(props.inertia, R0, w0, t)
    if which == "intermediate":  # it flips: the rate turns over to nearly the opposite sense of the axis
        assert (w @ axis).min() < -0.9 * rate and angle_from(w[:1], axis)[0] < 1.01 * tilt
    else:  # it stays a spin
        assert angle_from(w, axis).max() < 5 * tilt
    if which == "major":  # an exact spin (no tilt) is the closed form's; same kinematics both ways
        R_ib, w = integrate_tumble(props.inertia, R0, rate * axis, t)
        R_sp, w_sp = spin(R0, rate * axis, t)
        np.testing.assert_allclose(w, w_sp, atol=1e-12)
        np.testing.assert_allclose(R_ib, R_sp, atol=1e-8)  # ~1e-10 rad a radian over 2.6 turns


def test_each_attitude_mode_turns_at_its_body_rate_and_holds_what_it_holds(props):
    """The body rate each mode reports is the one its rotations turn at: R_IB^T dR_IB/dt = [w]x."""
    t = np.linspace(0.0, ORBIT.period, 2001)
    # central differences over h = 0.01 s err by (|w| h)^2 / 6 <= 1.3e-7 of |w| at 5 deg/s, the tumble's
    # dense output by ~rtol / h ~ 1e-8 rad/s; 1e-5 of |w| leaves a wide margin, a wrong frame is O(1)
    h = 0.01
    for mode in ATTITUDE_MODES:
        motion = draw_attitude(mode, np.random.default_rng(7), props)
        track = attitude_track(motion, N, t, props)
        if mode == "tumble":  # the integrator's dense output between frames: differentiate on a fine grid
            tf = np.array([100.0 - h, 100.0, 100.0 + h])
            fine = attitude_track(motion, N, tf, props)
            R_m, R_0, R_p, w = fine.R_ib[0], fine.R_ib[1], fine.R_ib[2], fine.omega_body[1]
        else:
            k = 700
            R_m = attitude_track(motion, N, np.array([t[k] - h]), props).R_ib[0]
            R_p = attitude_track(motion, N, np.array([t[k] + h]), props).R_ib[0]
            R_0, w = track.R_ib[k], track.omega_body[k]
        W = R_0.T @ (R_p - R_m) / (2 * h)
        # + 1e-12 for w = 0 (inertial): R_IB is R0 at every time, so W is exactly 0 and any margin holds
        np.testing.assert_allclose(
            0.5 * (W - W.T),
            [[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]],
            atol=1e-5 * np.linalg.norm(w) + 1e-12,
        )
        # held attitudes are products of exact rotations: equal to a few eps (2.2e-16) per entry
        if mode == "lvlh_hold":
            np.testing.assert_allclose(
                track.R_lb, np.broadcast_to(track.R_lb[0], track.R_lb.shape), atol=1e-12
            )
            # R0^T (0, 0, n): three unit-row dot products and a norm, a few u64 of n, not approx's 1e-6
            assert np.linalg.norm(track.omega_body[0]) == pytest.approx(N, rel=1e-14)
        if mode == "inertial":
            np.testing.assert_allclose(
                track.R_ib, np.broadcast_to(track.R_ib[0], track.R_ib.shape), atol=1e-15
            )
            np.testing.assert_allclose(track.R_lb[-1], track.R_lb[0], atol=1e-12)  # once around in LVLH
            assert np.abs(track.R_lb[1000] - track.R_lb[0]).max() > 1  # half an orbit: turned by 180 deg
        if mode == "spin":
            # w is rate * (a principal axis): a rounding per component, so within 4 eps of that axis
            w0 = track.omega_body[0]
            assert min(angle_from(w0, props.axis(a)) for a in ("minor", "major")) < 4 * EPS
            # and the spin is torque-free: w x J w (Euler's gyroscopic term) vanishes to eigh's residual,
            # |J v - l v| <= p(n) eps |J| (backward stable; p(3) < 10 n), plus J w's and the cross's own
            # roundings; by the sin-theta theorem w is then within 30 eps |J| / gap ~ 8e-14 rad of the
            # exact principal axis (the moments' smallest gap is 0.088 |J|)
            J = props.inertia
            assert np.linalg.norm(np.cross(w0, J @ w0)) < 30 * EPS * props.principal_moments[-1] * (w0 @ w0)
            assert 0.5 <= math.degrees(np.linalg.norm(track.omega_body[0])) <= 5.0
    with pytest.raises(ScgenError, match="unknown attitude mode"):
        draw_attitude("wobble", np.random.default_rng(0))
    with pytest.raises(ScgenError, match="needs the target's mass properties"):
        attitude_track(AttitudeMotion("tumble", (1.0, 0, 0, 0), (0.01, 0, 0)), N, t)
