"""Rendezvous sequences: the config's `[sequence]` table, and sequence s of a seed as SceneSpecs, one a frame.

A sequence draws, each from its own stream (`sequence_rng(seed, s, part)`), an orbit, a relative-motion
profile and an attitude motion (scgen.scenes.motion.orbit, scgen.scenes.motion.tumble), a sun fixed in
inertial space, a camera pointing and a camera (and, with `initial_attitude = "pose"`, the attitude at
t = 0 as the `[pose]` table draws an independent sample's: `initial_pose`); frame k at t_k = k dt is then
an ordinary SceneSpec, with the camera at the chaser (its frame the scene's world frame, as for every
sample), so the render, camera, annotation and writer paths are those of an independent sample. Every
frame is computed from the whole sequence at once (the tumble integrated over the whole span, the
pointing carried from frame to frame), so frame k is the same whatever frames are asked for. Pure
numpy/scipy; docs/sequences.md gives the equations.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from scgen.errors import ScgenError
from scgen.scenes.attitude import ConeDraw, sample_attitude
from scgen.scenes.config.camera import CameraSettings
from scgen.scenes.config.checks import check_choice, check_range, is_number
from scgen.scenes.finish import sample_finish
from scgen.scenes.geometry import matrix_to_quat
from scgen.scenes.imaging import sample_imaging
from scgen.scenes.motion.companions import Companion, companion_tracks
from scgen.scenes.motion.orbit import (
    NADIR_LVLH,
    PROFILES,
    Orbit,
    draw_orbit,
    draw_profile,
    draw_sun,
    earth_angular_radius,
    in_eclipse,
    lvlh_to_inertial,
    sun_direction_lvlh,
)
from scgen.scenes.motion.tumble import ATTITUDE_MODES, MassProperties, attitude_track, draw_attitude
from scgen.scenes.rng import choice, sequence_rng
from scgen.scenes.silhouette import TargetShape
from scgen.scenes.sky import celestial_frame, sky_background
from scgen.scenes.spec import (
    BackgroundSpec,
    CameraSpec,
    PlacedObject,
    Pose,
    SceneSpec,
    SequenceFrame,
    SunSpec,
)

EARTH_ROTATION_RAD_S = 7.2921159e-5  # the Earth's sidereal spin rate (IERS), turning its map under the orbit
POINTING_MODES = ("target", "fixed")
INITIAL_ATTITUDES = ("uniform", "pose")  # the target's attitude at t = 0: uniform over SO(3), or `[pose]`'s
SUNLIT = "normal"  # the illumination level of a sunlit frame: the sun's true irradiance
ECLIPSED = "eclipse"  # the level of a frame in the Earth's shadow: no sunlight

# The `[sequence]` table (docs/config.md#sequence): absent from a config without sequences, so an
# independent-frame dataset's config, and with it every byte it writes, is what it was.
DEFAULT_SEQUENCE: dict[str, Any] = {
    "frames": 10,  # frames per sequence (each sequence is one BOP scene)
    "dt_s": 1.0,  # s between frames
    "spacecraft_diameter_m": 3.0,  # the real target's diameter (m): profile metres x model diameter / this
    "altitude_km": [400.0, 800.0],  # circular orbit, altitude uniform over this range
    "max_beta_deg": 90.0,  # the sun's elevation over the orbit plane, uniform over the band |beta| <= this
    "profile_probs": {name: 1.0 / len(PROFILES) for name in PROFILES},  # scgen.scenes.motion.orbit.PROFILES
    "profiles": {},  # per profile, its ranges overriding DEFAULT_PROFILE_RANGES[profile]
    "attitude_probs": {mode: 1.0 / len(ATTITUDE_MODES) for mode in ATTITUDE_MODES},
    "initial_attitude": "uniform",  # uniform: over SO(3); pose: frame 0 seen as `[pose]` draws (initial_pose)
    "rate_deg": [0.5, 5.0],  # deg/s, spin and tumble rates
    "pointing": "target",  # target: the camera tracks the target; fixed: held in LVLH from frame 0
    "pointing_error_deg": 1.0,  # the boresight off the target by a constant angle uniform in [0, this]
    "roll_deg": [-180.0, 180.0],  # the camera's roll about the boresight at frame 0
}


def is_sequence(cfg: dict[str, Any]) -> bool:
    """Whether a resolved config renders sequences (it has a `sequence` table)."""
    return cfg.get("sequence") is not None


def merge_sequence(table: Any) -> dict[str, Any]:
    """DEFAULT_SEQUENCE overridden by a config file's `[sequence]` table: known keys only, each of its
    default's kind; `profile_probs` and `attitude_probs` replace the default map whole (a name left out
    has share 0), `profiles` maps a profile to its range overrides."""
    if not isinstance(table, dict):
        raise ScgenError("config key 'sequence' must be a table")
    out = copy.deepcopy(DEFAULT_SEQUENCE)
    for key, value in table.items():
        if key not in out:
            raise ScgenError(f"unknown config key 'sequence.{key}'; known: {', '.join(DEFAULT_SEQUENCE)}")
        default = out[key]
        if isinstance(default, dict) and not isinstance(value, dict):
            raise ScgenError(f"config key 'sequence.{key}' must be a table")
        if isinstance(default, list) and not isinstance(value, list):
            raise ScgenError(f"config key 'sequence.{key}' must be a list")
        if isinstance(default, str) and not isinstance(value, str):
            raise ScgenError(f"config key 'sequence.{key}' must be a string, got {value!r}")
        if isinstance(default, (int, float)) and (isinstance(value, bool) or not is_number(value)):
            raise ScgenError(f"config key 'sequence.{key}' must be a number, got {value!r}")
        out[key] = copy.deepcopy(value)
    return out


def check_sequence(seq: dict[str, Any]) -> None:
    """Every value of a merged `sequence` table in range, each profile's ranges drawable."""
    if not isinstance(seq["frames"], int) or seq["frames"] <= 0:
        raise ScgenError(f"sequence.frames must be a positive integer, got {seq['frames']!r}")
    for key in ("dt_s", "spacecraft_diameter_m"):
        if not seq[key] > 0:
            raise ScgenError(f"sequence.{key} must be positive, got {seq[key]}")
    check_range("sequence.altitude_km", seq["altitude_km"], low=1.0)
    check_range("sequence.rate_deg", seq["rate_deg"], low=0.0)
    check_range("sequence.roll_deg", seq["roll_deg"], low=-360.0)
    if not 0.0 <= seq["max_beta_deg"] <= 90.0:
        raise ScgenError(f"sequence.max_beta_deg must lie in [0, 90], got {seq['max_beta_deg']}")
    if not 0.0 <= seq["pointing_error_deg"] < 90.0:
        raise ScgenError(f"sequence.pointing_error_deg must lie in [0, 90), got {seq['pointing_error_deg']}")
    if seq["pointing"] not in POINTING_MODES:
        raise ScgenError(
            f"sequence.pointing must be one of {', '.join(POINTING_MODES)}, got {seq['pointing']!r}"
        )
    check_choice("sequence.initial_attitude", seq["initial_attitude"], INITIAL_ATTITUDES)
    for key, names in (("profile_probs", PROFILES), ("attitude_probs", ATTITUDE_MODES)):
        probs = seq[key]
        unknown = sorted(set(probs) - set(names))
        if unknown:
            raise ScgenError(f"sequence.{key}: unknown {', '.join(unknown)}; choose from {', '.join(names)}")
        if not all(is_number(p) and p >= 0 for p in probs.values()) or not sum(probs.values()) > 0:
            raise ScgenError(f"sequence.{key} must give non-negative shares, not all 0, got {probs}")
    unknown = sorted(set(seq["profiles"]) - set(PROFILES))
    if unknown:
        raise ScgenError(
            f"sequence.profiles: unknown profile {', '.join(unknown)}; choose from {', '.join(PROFILES)}"
        )
    for name, ranges in seq["profiles"].items():
        if not isinstance(ranges, dict):
            raise ScgenError(f"sequence.profiles.{name} must be a table of ranges")
        draw_profile(name, np.random.default_rng(0), ranges)  # names an unknown key or a bad range


# ---------------------------------------------------------------------------------------------------------
# the camera's pointing


def look_basis(d: np.ndarray, roll: float) -> np.ndarray:
    """A camera (OpenCV axes) looking along unit d (LVLH), rolled by `roll` (rad) about it from the camera
    whose image 'up' is towards zenith (+R-bar; the orbit normal when d is within 8 deg of R-bar):
    R_LC, its columns the camera's x, y, z in LVLH."""
    up = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.99 else np.array([0.0, 0.0, 1.0])
    x = np.cross(d, up)
    x /= np.linalg.norm(x)
    y = np.cross(d, x)
    c, s = math.cos(roll), math.sin(roll)
    return np.stack([c * x + s * y, -s * x + c * y, d], axis=1)


def initial_camera(profile: Any, n: float, roll: float, error: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R_LC at t = 0 (the same for both pointings: the boresight on the target's centre of mass, rolled,
    then turned by the pointing error) and the unit ray from the camera to that centre, camera axes."""
    r, _ = profile.state(n, 0.0)
    d = -r / np.linalg.norm(r)
    R_lc = look_basis(d, roll) @ error
    return R_lc, R_lc.T @ d


def minimal_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit a onto unit b (about a x b)."""
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(np.dot(a, b))
    if s < 1e-15:
        return np.eye(3)
    return Rotation.from_rotvec(axis / s * math.atan2(s, c)).as_matrix()


def track_pointing(d: np.ndarray, R0: np.ndarray) -> np.ndarray:
    """R_LC at each frame of a camera that keeps its boresight on the directions d (T, 3) turning by the
    smallest rotation from each frame to the next (no roll about the boresight: parallel transport)."""
    out = np.empty((len(d), 3, 3))
    out[0] = R0
    for k in range(1, len(d)):
        out[k] = minimal_rotation(d[k - 1], d[k]) @ out[k - 1]
    return out


# ---------------------------------------------------------------------------------------------------------
# a sequence


@dataclass(frozen=True)
class SequenceDraw:
    """What sequence s of a seed drew: the orbit's altitude, the profile, the attitude motion, the sun,
    the pointing (roll at frame 0; pointing error as a rotation of the camera, camera axes), the sky, and
    with `initial_attitude = "pose"` a cone `[pose]` table's draw for frame 0 (else None)."""

    altitude_m: float
    profile: Any  # an scgen.scenes.motion.orbit profile
    attitude: Any  # scgen.scenes.motion.tumble.AttitudeMotion
    sun: Any  # scgen.scenes.motion.orbit.Sun
    roll_rad: float
    error: np.ndarray  # 3x3, camera (pointing at the target) -> camera (as it points)
    sky_longitude: float  # the sun's ecliptic longitude (a date) and the sky's roll about it (rad)
    sky_roll: float
    earth_spin_deg: float  # the Earth's sidereal angle at t = 0
    cone: ConeDraw | None = None  # frame 0's place in the `[pose]` corridor (initial_attitude "pose", cone)


def initial_pose(
    rng: np.random.Generator, pose: dict[str, Any], R_lc: np.ndarray, ray: np.ndarray
) -> tuple[tuple[float, float, float, float], ConeDraw | None]:
    """The target's attitude at t = 0, body -> LVLH (= body -> I then) as a quaternion (w, x, y, z), for
    which the camera R_LC sees it as an independent sample drawn from the `pose` table on `ray` would be
    (scgen.scenes.attitude.sample_attitude): R = R_LC^T R_LB, so R_LB = R_LC R. And the cone draw.

    `ray` is the ray to the centre of mass, not to the model origin an independent sample's t holds: the
    origin sits at t = com - R c, which depends on the R being drawn, while the centre of mass is where
    the camera points (off by the pointing error) and the point the motion turns about. The two rays part
    by at most asin(|c| / |com|), |c| the centre of mass's offset from the model origin."""
    R, cone = sample_attitude(rng, pose, ray)
    q = Rotation.from_matrix(R_lc @ R).as_quat()[[3, 0, 1, 2]]
    return tuple(float(x) for x in q), cone


def draw_sequence(
    seed: int, sequence: int, seq: dict[str, Any], props: MassProperties, pose: dict[str, Any] | None = None
) -> SequenceDraw:
    """Sequence `sequence`'s draws, each from its own stream; `pose` (the config's `[pose]` table) is
    needed with `initial_attitude = "pose"`, whose draw has its own stream too and replaces only the
    attitude motion's uniform attitude at t = 0 (still drawn, so the motion's rates are the same)."""
    orbit = draw_orbit(sequence_rng(seed, sequence, "orbit"), tuple(seq["altitude_km"]))
    rng = sequence_rng(seed, sequence, "profile")
    name = choice(rng, seq["profile_probs"])
    profile = draw_profile(name, rng, seq["profiles"].get(name))
    rng = sequence_rng(seed, sequence, "attitude")
    attitude = draw_attitude(choice(rng, seq["attitude_probs"]), rng, props, tuple(seq["rate_deg"]))
    sun = draw_sun(sequence_rng(seed, sequence, "sun"), seq["max_beta_deg"])
    rng = sequence_rng(seed, sequence, "pointing")
    roll = math.radians(rng.uniform(*seq["roll_deg"]))
    off = math.radians(rng.uniform(0.0, seq["pointing_error_deg"]))
    az = rng.uniform(0.0, 2.0 * math.pi)
    error = Rotation.from_rotvec(off * np.array([math.sin(az), -math.cos(az), 0.0])).as_matrix()
    lam, sky_roll, spin = sequence_rng(seed, sequence, "sky").uniform(0.0, 2.0 * math.pi, 3)
    cone = None
    if seq["initial_attitude"] == "pose":
        if pose is None:
            raise ScgenError('sequence.initial_attitude "pose" needs the config\'s [pose] table')
        R_lc, ray = initial_camera(profile, orbit.n, roll, error)
        q0, cone = initial_pose(sequence_rng(seed, sequence, "pose"), pose, R_lc, ray)
        attitude = replace(attitude, q0=q0)
    return SequenceDraw(orbit.altitude_m, profile, attitude, sun, roll, error, lam, sky_roll,
                        math.degrees(spin), cone)  # fmt: skip


@dataclass(frozen=True)
class Track:
    """A sequence's geometry at each frame time, in the camera frame (model-frame metres): the target's
    pose (R, t), their rates (dt/dt, angular velocity, camera axes), R_LC, the camera's rate relative to
    LVLH (camera axes), the chaser's thrust acceleration (LVLH, model-frame metres), the sun, the Earth's
    centre direction, the eclipse flag, the range (real metres), and R_CI (inertial -> camera)."""

    t_s: np.ndarray
    R: np.ndarray
    t: np.ndarray
    velocity: np.ndarray
    omega: np.ndarray
    R_lc: np.ndarray
    camera_rate: np.ndarray
    thrust: np.ndarray
    sun: np.ndarray
    nadir: np.ndarray
    eclipse: np.ndarray
    range_m: np.ndarray
    R_ci: np.ndarray


def sequence_track(
    draw: SequenceDraw, times: np.ndarray, scale: float, props: MassProperties, pointing: str
) -> Track:
    """The relative geometry of a drawn sequence at `times` (s, from 0), with positions and velocities of
    the real spacecraft scaled by `scale` (model diameter / spacecraft diameter; HCW is linear).

    The camera sits at the chaser, its boresight on the target's centre of mass (then turned by the
    pointing error) and carried frame to frame without roll (pointing 'target'), or held in LVLH as it
    was at frame 0 (pointing 'fixed'). With R_LC the camera's attitude in LVLH, R_LB the target's, c its
    centre of mass (model frame) and r the chaser's position (LVLH):

        R = R_LC^T R_LB,   t = R_LC^T (-s r) - R c,
        w = R_LC^T (R_LB w_body - n z - w_CL),   dt/dt = R_LC^T (-s v + w_CL x s r) - w x (R c)

    where w_CL = d x d' is the tracking camera's rate in LVLH (d = -r/|r|; 0 when fixed) and n z LVLH's
    rate about the orbit normal.
    """
    orbit = Orbit(draw.altitude_m)
    a, n = orbit.a, orbit.n
    r, v = draw.profile.state(n, times)
    rho = np.linalg.norm(r, axis=-1)
    if np.any(rho <= 0):
        raise ScgenError(f"the {draw.profile.name} profile puts the chaser on the target")
    d = -r / rho[:, None]
    R0 = look_basis(d[0], draw.roll_rad)
    if pointing == "target":
        R_lc = track_pointing(d, R0) @ draw.error
        d_dot = -(v - d * np.sum(d * v, axis=-1, keepdims=True)) / rho[:, None]
        w_cl = np.cross(d, d_dot)
    else:
        R_lc = np.repeat((R0 @ draw.error)[None], len(times), 0)
        w_cl = np.zeros_like(r)
    R_cl = np.swapaxes(R_lc, -1, -2)
    att = attitude_track(draw.attitude, n, times, props)
    R = R_cl @ att.R_lb
    com = np.einsum("kij,kj->ki", R_cl, -scale * r)
    Rc = R @ props.centre_of_mass
    t = com - Rc
    w_l = np.einsum("kij,kj->ki", att.R_lb, att.omega_body) - np.array([0.0, 0.0, n]) - w_cl
    omega = np.einsum("kij,kj->ki", R_cl, w_l)
    velocity = np.einsum("kij,kj->ki", R_cl, -scale * v + np.cross(w_cl, scale * r)) - np.cross(omega, Rc)
    sun_l = sun_direction_lvlh(draw.sun, n, times)
    R_ci = R_cl @ np.swapaxes(lvlh_to_inertial(n, times), -1, -2)
    camera_rate = np.einsum("kij,kj->ki", R_cl, w_cl)
    thrust = scale * draw.profile.thrust(n, times)
    sun = np.einsum("kij,kj->ki", R_cl, sun_l)
    return Track(times, R, t, velocity, omega, R_lc, camera_rate, thrust, sun, R_cl @ NADIR_LVLH,
                 in_eclipse(sun_l, a), rho, R_ci)  # fmt: skip


def motion_blur(
    camera: CameraSpec, t: np.ndarray, velocity: np.ndarray, exposure_s: float
) -> tuple[float, float]:
    """(length px, direction deg in [0, 180)) of the target centre's image motion during the exposure:
    d(u, v)/dt = f (x' z - x z') / z^2 (pinhole) times the exposure time."""
    x, y, z = t
    vx, vy, vz = velocity
    K = camera.K_mat
    du = K[0, 0] * (vx * z - x * vz) / z**2 * exposure_s
    dv = K[1, 1] * (vy * z - y * vz) / z**2 * exposure_s
    return float(math.hypot(du, dv)), float(math.degrees(math.atan2(dv, du)) % 180.0)


def sample_sequence(
    seed: int, sequence: int, cfg: dict[str, Any], shape: TargetShape, props: MassProperties,
    companions: Sequence[Companion] = (),
) -> list[SceneSpec]:  # fmt: skip
    """The SceneSpecs of every frame of sequence `sequence` of `seed`; frame k has sample index
    sequence * frames + k. Depends only on (seed, sequence, cfg, the objects' geometry). `companions`:
    the config's `[[objects]]` entries (scgen.scenes.motion.companions), from their own stream."""
    seq = cfg["sequence"]
    frames = seq["frames"]
    draw = draw_sequence(seed, sequence, seq, props, cfg["pose"])
    times = np.arange(frames) * float(seq["dt_s"])
    scale = shape.diameter / seq["spacecraft_diameter_m"]
    track = sequence_track(draw, times, scale, props, seq["pointing"])
    objects = companion_poses(seed, sequence, seq, draw, times, track, scale, shape, companions)
    camera = CameraSpec.from_config(cfg["camera"])
    settings = CameraSettings.from_table(cfg["camera"])
    imaging = sample_imaging(sequence_rng(seed, sequence, "camera"), settings)
    blur = settings.optics.motion_blur_prob > 0  # the camera models motion blur: the true motion's
    finish = sample_finish(sequence_rng(seed, sequence, "finish"), cfg["finish"])
    bg_cfg = cfg["background"]
    bg_seed = int(sequence_rng(seed, sequence, "background").integers(2**31))
    ill = cfg["illumination"]
    rho_earth = earth_angular_radius(Orbit(draw.altitude_m).a)
    K = camera.K_mat
    half_diag = math.atan(math.hypot(0.5 * camera.width / K[0, 0], 0.5 * camera.height / K[1, 1]))
    icrs_to_i = celestial_frame(draw.sun.inertial(), draw.sky_longitude, draw.sky_roll)
    specs = []
    for k in range(frames):
        index = sequence * frames + k
        eclipse = bool(track.eclipse[k])
        nadir = track.nadir[k]
        kind = "earth" if math.acos(np.clip(nadir[2], -1.0, 1.0)) < rho_earth + half_diag else "clean"
        params: dict[str, Any] = {}
        if kind == "earth":
            params = {"centre_dir": [float(c) for c in nadir], "angular_radius_deg": math.degrees(rho_earth),
                      "albedo": float(bg_cfg["earth_albedo"]), "limb": True}  # fmt: skip
        spin_deg = (draw.earth_spin_deg + math.degrees(EARTH_ROTATION_RAD_S * times[k])) % 360.0
        sky = {
            "sky_frame": [float(x) for x in (track.R_ci[k] @ icrs_to_i).ravel()],
            "earth_spin_deg": spin_deg,
        }
        params.update(sky_background(kind, bg_cfg, sky))
        level = ECLIPSED if eclipse else SUNLIT
        irradiance = 0.0 if eclipse else ill["solar_irradiance"] * ill["multipliers"][SUNLIT]
        frame_imaging = imaging
        if blur:
            exposure_s = settings.sensor.exposure_time_s
            length, angle = motion_blur(camera, track.t[k], track.velocity[k], exposure_s)
            frame_imaging = replace(imaging, motion_blur_px=length, motion_blur_deg=angle)
        t = track.t[k]
        specs.append(
            SceneSpec(
                seed=int(seed),
                index=int(index),
                camera=camera,
                target=Pose.from_arrays(track.R[k], t),
                distance_m=float(np.linalg.norm(t)),
                sun=SunSpec(tuple(float(x) for x in track.sun[k]), level, float(irradiance)),
                background=BackgroundSpec(kind, bg_seed, params),
                props=(),
                requested_occlusion="none",
                shadow_caster=False,
                imaging=frame_imaging,
                finish=finish,
                objects=tuple(frame[k] for frame in objects),
                sequence=SequenceFrame(
                    sequence=int(sequence),
                    frame=k,
                    time_s=float(times[k]),
                    velocity=tuple(float(x) for x in track.velocity[k]),
                    angular_velocity=tuple(float(x) for x in track.omega[k]),
                    eclipse=eclipse,
                    profile=draw.profile.name,
                    attitude=draw.attitude.mode,
                    range_m=float(track.range_m[k]),
                    altitude_km=draw.altitude_m / 1e3,
                    camera_attitude=tuple(float(x) for x in matrix_to_quat(track.R_lc[k])),
                    camera_rate=tuple(float(x) for x in track.camera_rate[k]),
                    thrust=tuple(float(x) for x in track.thrust[k]),
                ),
            )  # fmt: skip
        )
    return specs


def companion_poses(
    seed: int, sequence: int, seq: dict[str, Any], draw: SequenceDraw, times: np.ndarray, track: Track,
    scale: float, shape: TargetShape, companions: Sequence[Companion],
) -> list[list[PlacedObject]]:  # fmt: skip
    """Each `[[objects]]` instance's pose at every frame (instance by instance), on its own orbit about the
    target (companion_tracks): R = R_LC^T R_LB, t = R_LC^T s (p - r) - R c, as the target's, with p its
    centre of mass relative to the target's and c its own centre of mass (model frame)."""
    if not companions:
        return []
    n = Orbit(draw.altitude_m).n
    chaser = draw.profile.state(n, times)[0]
    rng = sequence_rng(seed, sequence, "objects")
    paths = companion_tracks(rng, companions, seq, n, times, chaser, scale, shape.radius)
    centre = {c.obj_id: c.mass.centre_of_mass for c in companions}
    R_cl = np.swapaxes(track.R_lc, -1, -2)
    out = []
    for path in paths:
        R = R_cl @ path.R_lb
        t = np.einsum("kij,kj->ki", R_cl, scale * (path.com - chaser)) - R @ centre[path.obj_id]
        out.append([PlacedObject(path.obj_id, Pose.from_arrays(R[k], t[k])) for k in range(len(times))])
    return out
