"""SceneSpec: the pure-data description of one sample, shared by every backend.

All geometry is in the OpenCV camera frame (x right, y down, z forward), in metres.
The camera sits at the origin, so the camera frame doubles as the world frame.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np


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
    """Pinhole camera: K in pixels (row-major), image size, and the exposure in EV (logged, never silent)."""

    width: int
    height: int
    K: tuple[float, ...]
    exposure_ev: float

    @property
    def K_mat(self) -> np.ndarray:
        return np.asarray(self.K, dtype=np.float64).reshape(3, 3)


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
class BackgroundSpec:
    """Background kind (clean/complex/earth/cluttered/user) with its own seed and kind-specific parameters."""

    kind: str
    seed: int
    params: dict[str, Any] = field(default_factory=dict)


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

    @property
    def occluders(self) -> tuple[PropSpec, ...]:
        return tuple(p for p in self.props if p.role == "occluder")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @staticmethod
    def from_dict(d: dict[str, Any]) -> SceneSpec:
        def pose(p: dict[str, Any]) -> Pose:
            return Pose(tuple(p["R"]), tuple(p["t"]))

        cam = d["camera"]
        return SceneSpec(
            seed=int(d["seed"]),
            index=int(d["index"]),
            camera=CameraSpec(
                int(cam["width"]), int(cam["height"]), tuple(cam["K"]), float(cam["exposure_ev"])
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
        )
