"""SceneSpec: the pure-data description of one sample, shared by every backend.

All geometry is in the OpenCV camera frame (x right, y down, z forward), in metres.
The camera sits at the origin, so the camera frame doubles as the world frame.
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from scgen.io import bop
from scgen.scenes.attitude import ConeDraw
from scgen.scenes.config.camera import CameraSettings
from scgen.scenes.geometry import focal_length, project
from scgen.scenes.lens import distort, is_pinhole, undistort


@dataclass(frozen=True)
class Pose:
    """Rigid transform model -> camera: X_cam = R @ X_model + t (R row-major, t in metres)."""

    R: tuple[float, ...]
    t: tuple[float, ...]

    @property
    def R_mat(self) -> np.ndarray:
        return np.asarray(self.R, dtype=np.float64).reshape(3, 3)

    @property
    def t_vec(self) -> np.ndarray:
        return np.asarray(self.t, dtype=np.float64)

    @property
    def matrix(self) -> np.ndarray:
        """The 4x4 homogeneous transform."""
        m = np.eye(4)
        m[:3, :3] = self.R_mat
        m[:3, 3] = self.t_vec
        return m

    @staticmethod
    def from_arrays(R: np.ndarray, t: np.ndarray) -> Pose:
        return Pose(tuple(float(x) for x in np.asarray(R).reshape(9)), tuple(float(x) for x in np.asarray(t)))


@dataclass(frozen=True)
class CameraSpec:
    """Camera: K in pixels (row-major), image size, the base exposure in EV, and OpenCV's lens distortion
    (k1, k2, p1, p2, k3; empty or zero: pinhole). Rays and projections go through the lens exactly."""

    width: int
    height: int
    K: tuple[float, ...]
    exposure_ev: float
    dist: tuple[float, ...] = ()

    @property
    def pinhole(self) -> bool:
        return is_pinhole(self.dist)

    @property
    def K_mat(self) -> np.ndarray:
        return np.asarray(self.K, dtype=np.float64).reshape(3, 3)

    @staticmethod
    def from_config(camera: dict[str, Any]) -> CameraSpec:
        """From the config's camera section (resolved: cx, cy filled in)."""
        c = camera
        K = (c["fx"], 0.0, c["cx"], 0.0, c["fy"], c["cy"], 0.0, 0.0, 1.0)
        dist = tuple(float(k) for k in c.get("dist") or ())
        return CameraSpec(c["width"], c["height"], tuple(float(k) for k in K), float(c["exposure_ev"]),
                          () if is_pinhole(dist) else dist)  # fmt: skip

    @staticmethod
    def from_scene_camera(entry: dict[str, Any], width: int, height: int) -> CameraSpec:
        """The camera of a scene_camera.json entry: cam_K and, where present, the lens' cam_dist."""
        dist = bop.camera_dist(entry)
        K = tuple(float(k) for k in entry["cam_K"])
        exposure_ev = float(entry.get("exposure_ev", 0.0))
        return CameraSpec(width, height, K, exposure_ev, () if is_pinhole(dist) else dist)

    @property
    def focal(self) -> float:
        """Mean focal length (px): projected size = focal * size / depth."""
        return focal_length(self.K_mat)

    def rays(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Camera-frame rays (z = 1) through pixel positions (..., 3), centres at integers: K^-1 [u, v, 1],
        undistorted through the lens when it has distortion."""
        rays = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(self.K_mat).T
        if not self.pinhole:
            rays[..., :2] = undistort(rays[..., :2], self.dist)
        return rays

    def project(self, X: np.ndarray) -> np.ndarray:
        """Pixel coordinates (N x 2) of camera-frame points X (N x 3, z > 0), through the lens."""
        if self.pinhole:
            return project(self.K_mat, X)
        xy = distort(X[:, :2] / X[:, 2:3], self.dist)
        return project(self.K_mat, np.concatenate([xy, np.ones((len(xy), 1))], axis=1))

    def pixel_rays(self) -> np.ndarray:
        """Rays (z = 1) through every pixel centre, H x W x 3, float64, read-only (_pixel_grids)."""
        return self._pixel_grids()[0]

    def pixel_directions(self) -> np.ndarray:
        """Unit camera-frame directions through every pixel centre, H x W x 3, float64, read-only."""
        return self._pixel_grids()[1]

    def _pixel_grids(self) -> tuple[np.ndarray, np.ndarray]:
        """pixel_rays and pixel_directions, made once for a camera's geometry (its exposure aside): the
        annotation, the sky and Mitsuba's label rays take them every sample."""
        geometry = replace(self, exposure_ev=0.0)
        try:
            return _pixel_grids(geometry)
        except TypeError:  # a camera built with lists is unhashable: made each time
            return _pixel_grids.__wrapped__(geometry)


@functools.lru_cache(maxsize=2)
def _pixel_grids(camera: CameraSpec) -> tuple[np.ndarray, np.ndarray]:
    """`camera`'s rays (z = 1) and unit directions through every pixel centre, H x W x 3, read-only."""
    v, u = np.mgrid[0 : camera.height, 0 : camera.width].astype(np.float64)
    rays = camera.rays(u, v)
    directions = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
    rays.flags.writeable = directions.flags.writeable = False
    return rays, directions


@dataclass(frozen=True)
class SunSpec:
    """Directional sun: unit direction from the scene towards the sun (camera frame), level label, W/m^2."""

    direction: tuple[float, ...]
    level: str
    irradiance: float


@dataclass(frozen=True)
class PropSpec:
    """A non-target object: an occluder, a shadow caster or background clutter.

    `shape` picks a procedural primitive (see scgen.scenes.props), `size` its local box extents
    in metres, `pose` its placement (local -> camera), `seed` its shape details.
    """

    role: str
    shape: str
    size: tuple[float, ...]
    pose: Pose
    material: str
    seed: int


@dataclass(frozen=True)
class PlacedObject:
    """A labelled object beside the target (the config's `[[objects]]`): its BOP obj_id and its pose
    (model -> camera). It is drawn, occludes and is labelled as the target is: scene_gt entry 1 + its
    index in SceneSpec.objects, instance id buffers.object_instance_id(that index)."""

    obj_id: int
    pose: Pose


@dataclass(frozen=True)
class BackgroundSpec:
    """Background kind (clean/complex/earth/cluttered/user) with its own seed and kind-specific parameters."""

    kind: str
    seed: int
    params: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ImagingSpec:
    """The camera stage's per-image draws (scgen.scenes.imaging) and the camera settings they came from.

    ev_shift: EV added to the base exposure (0 in fixed and auto mode: auto decides it from the image);
    gain: analog gain (the noise level); psf_fwhm_px; motion blur length (px) and direction (deg);
    vignetting (light lost at the farthest corner); chromatic_px; jpeg_quality; noise_seed seeds the
    pixel noise and the flare's ghosts. `camera` is the camera's typed settings (sensor, optics, ...).
    """

    ev_shift: float
    gain: float
    psf_fwhm_px: float
    motion_blur_px: float
    motion_blur_deg: float
    vignetting: float
    chromatic_px: float
    jpeg_quality: int
    noise_seed: int
    camera: CameraSettings = field(default_factory=CameraSettings)


SEQUENCE_COLUMNS = (
    "sequence_id", "frame", "time_s", "vx", "vy", "vz", "wx", "wy", "wz", "eclipse", "profile",
    "attitude_mode", "range_m", "altitude_km",
    "cam_qw", "cam_qx", "cam_qy", "cam_qz", "cam_wx", "cam_wy", "cam_wz", "thrust_x", "thrust_y", "thrust_z",
)  # fmt: skip  # metadata.csv's columns of a sequence frame (docs/dataset.md)


@dataclass(frozen=True)
class SequenceFrame:
    """Where a frame sits in its rendezvous sequence (scgen.scenes.motion.sequence) and the motion there.

    `velocity`: d t / dt, the rate of the labelled translation t (m/s, model-frame metres, camera axes);
    `angular_velocity`: the target's angular velocity relative to the camera (rad/s, camera axes), so
    dR/dt = [w]x R. `range_m` is the chaser-target distance in metres of the real spacecraft (before the
    scale to the model); `eclipse`: the target in the Earth's shadow.

    What the chaser knows of itself, which a navigation filter may use (posenet.navigation): its camera's
    attitude in LVLH `camera_attitude` (a quaternion w, x, y, z, camera -> LVLH), the camera's angular
    velocity relative to LVLH `camera_rate` (rad/s, camera axes), and its own thrust acceleration
    `thrust` (LVLH axes, m/s^2 of the model frame's scale, as velocity is; impulses not included).
    """

    sequence: int
    frame: int
    time_s: float
    velocity: tuple[float, float, float]
    angular_velocity: tuple[float, float, float]
    eclipse: bool
    profile: str
    attitude: str
    range_m: float
    altitude_km: float
    camera_attitude: tuple[float, float, float, float]
    camera_rate: tuple[float, float, float]
    thrust: tuple[float, float, float]

    def labels(self) -> dict[str, Any]:
        """The metadata.csv columns (SEQUENCE_COLUMNS) of this frame."""
        (vx, vy, vz), (wx, wy, wz) = self.velocity, self.angular_velocity
        values = (self.sequence, self.frame, self.time_s, vx, vy, vz, wx, wy, wz, int(self.eclipse),
                  self.profile, self.attitude, self.range_m, self.altitude_km, *self.camera_attitude,
                  *self.camera_rate, *self.thrust)  # fmt: skip
        return dict(zip(SEQUENCE_COLUMNS, values, strict=True))


@dataclass(frozen=True)
class SceneSpec:
    """Everything a backend needs to render sample `index` of `seed`, and every sampled factor's label."""

    seed: int
    index: int
    camera: CameraSpec
    target: Pose
    distance_m: float
    sun: SunSpec
    background: BackgroundSpec
    props: tuple[PropSpec, ...]
    requested_occlusion: str
    shadow_caster: bool
    imaging: ImagingSpec | None = None  # None: the ideal camera (no stage draws)
    finish: dict[str, dict[str, Any]] = field(default_factory=dict)  # scgen.scenes.finish; {}: nominal
    cone: ConeDraw | None = None  # a cone attitude's place in its corridor (scgen.scenes.attitude)
    sequence: SequenceFrame | None = None  # a rendezvous sequence's frame (scgen.scenes.motion.sequence)
    objects: tuple[PlacedObject, ...] = ()  # the other labelled objects (config `[[objects]]`)

    @property
    def occluders(self) -> tuple[PropSpec, ...]:
        return tuple(p for p in self.props if p.role == "occluder")

    def to_dict(self) -> dict[str, Any]:
        """Plain data; `cone`, `sequence` and `objects` only when set, so a one-object independent sample's
        record is what it always was."""
        d = asdict(self)
        for key in ("cone", "sequence", "objects"):
            if not d[key]:
                del d[key]
        return d

    @staticmethod
    def from_dict(d: dict[str, Any]) -> SceneSpec:
        def pose(p: dict[str, Any]) -> Pose:
            return Pose(tuple(p["R"]), tuple(p["t"]))

        cam = d["camera"]
        return SceneSpec(
            seed=int(d["seed"]),
            index=int(d["index"]),
            camera=CameraSpec(
                int(cam["width"]),
                int(cam["height"]),
                tuple(cam["K"]),
                float(cam["exposure_ev"]),
                tuple(cam.get("dist", ())),
            ),
            target=pose(d["target"]),
            distance_m=float(d["distance_m"]),
            sun=SunSpec(tuple(d["sun"]["direction"]), d["sun"]["level"], float(d["sun"]["irradiance"])),
            background=BackgroundSpec(
                d["background"]["kind"], int(d["background"]["seed"]), d["background"]["params"]
            ),
            props=tuple(
                PropSpec(
                    p["role"], p["shape"], tuple(p["size"]), pose(p["pose"]), p["material"], int(p["seed"])
                )
                for p in d["props"]
            ),
            requested_occlusion=d["requested_occlusion"],
            shadow_caster=bool(d["shadow_caster"]),
            imaging=_imaging(d["imaging"]) if d.get("imaging") else None,
            finish=d.get("finish", {}),
            cone=ConeDraw(**d["cone"]) if d.get("cone") else None,
            sequence=_sequence_frame(d["sequence"]) if d.get("sequence") else None,
            objects=tuple(PlacedObject(int(o["obj_id"]), pose(o["pose"])) for o in d.get("objects", ())),
        )


def _sequence_frame(d: dict[str, Any]) -> SequenceFrame:
    vectors = ("velocity", "angular_velocity", "camera_attitude", "camera_rate", "thrust")
    return SequenceFrame(**{**d, **{k: tuple(d[k]) for k in vectors}})


def _imaging(d: dict[str, Any]) -> ImagingSpec:
    return ImagingSpec(**{**d, "camera": CameraSettings.from_table(d["camera"])})
