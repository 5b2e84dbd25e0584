"""Sample the SceneSpec of sample `index` of `seed`: pure, deterministic, renderer-free."""

from __future__ import annotations

from typing import Any

import numpy as np

from scgen.scenes.config import distance_range_m
from scgen.scenes.geometry import (
    backproject,
    look_rotation,
    orthonormal_basis,
    random_direction_in_cone,
    random_rotation,
    random_unit_vector,
)
from scgen.scenes.rng import factor_rng
from scgen.scenes.spec import BackgroundSpec, CameraSpec, Pose, PropSpec, SceneSpec, SunSpec

OCCLUDER_SHAPES = ("panel", "box", "rod", "debris", "arm")
CLUTTER_SHAPES = ("box", "panel", "debris", "truss")
PROP_MATERIALS = ("white_paint", "brushed_metal", "mli_silver", "dark_metal", "mli_gold")

# Centre offset between occluder and target, in target projected radii, per requested occlusion group.
OCCLUSION_OFFSETS = {"slight": (0.95, 1.35), "moderate": (0.55, 0.95), "heavy": (0.0, 0.55)}


def _choice(rng: np.random.Generator, probs: dict[str, float]) -> str:
    names = list(probs)
    p = np.array([probs[n] for n in names], dtype=float)
    return names[int(rng.choice(len(names), p=p / p.sum()))]


def camera_from_config(cfg: dict[str, Any]) -> CameraSpec:
    c = cfg["camera"]
    K = (c["fx"], 0.0, c["cx"], 0.0, c["fy"], c["cy"], 0.0, 0.0, 1.0)
    return CameraSpec(c["width"], c["height"], tuple(float(k) for k in K), float(c["exposure_ev"]))


def sample_scene(seed: int, index: int, cfg: dict[str, Any], diameter_m: float) -> SceneSpec:
    """The SceneSpec of one sample; depends only on (seed, index, cfg, model diameter)."""
    camera = camera_from_config(cfg)
    K = camera.K_mat
    f = 0.5 * (K[0, 0] + K[1, 1])

    R = random_rotation(factor_rng(seed, index, "pose"))

    z_min, z_max = distance_range_m(cfg, diameter_m)
    z = float(factor_rng(seed, index, "distance").uniform(z_min, z_max))
    radius_px = f * 0.5 * diameter_m / z

    pos_rng = factor_rng(seed, index, "position")
    margin = min(cfg["position"]["inside_radius_frac"] * radius_px, 0.45 * min(camera.width, camera.height))
    u = pos_rng.uniform(margin, camera.width - 1 - margin)
    v = pos_rng.uniform(margin, camera.height - 1 - margin)
    t = backproject(K, u, v, z)

    sun = _sample_sun(factor_rng(seed, index, "illumination"), cfg["illumination"], t)
    caster = _sample_shadow_caster(factor_rng(seed, index, "shadow"), cfg["shadow"], t, sun, diameter_m)
    background, clutter = _sample_background(
        factor_rng(seed, index, "background"), cfg["background"], K, camera, z, radius_px
    )
    occ_group, occluders = _sample_occluders(
        factor_rng(seed, index, "occluders"), cfg["occluders"], K, camera, (u, v), z, radius_px
    )
    return SceneSpec(
        seed=int(seed),
        index=int(index),
        camera=camera,
        target=Pose.from_arrays(R, t),
        distance_m=float(np.linalg.norm(t)),
        sun=sun,
        background=background,
        props=tuple(occluders + caster + clutter),
        requested_occlusion=occ_group,
        shadow_caster=bool(caster),
    )


def _sample_sun(rng: np.random.Generator, cfg: dict[str, Any], t: np.ndarray) -> SunSpec:
    level = _choice(rng, cfg["probs"])
    to_camera = -t / np.linalg.norm(t)
    direction = random_direction_in_cone(rng, to_camera, np.deg2rad(cfg["max_phase_deg"]))
    irradiance = cfg["solar_irradiance"] * cfg["multipliers"][level]
    return SunSpec(tuple(float(x) for x in direction), level, float(irradiance))


def _sample_shadow_caster(
    rng: np.random.Generator, cfg: dict[str, Any], t: np.ndarray, sun: SunSpec, diameter: float
) -> list[PropSpec]:
    """A plate between the sun and the target, offset sideways so it shades part of it."""
    if rng.uniform() >= cfg["caster_prob"]:
        return []
    s = np.asarray(sun.direction)
    a, b = orthonormal_basis(s)
    phi = rng.uniform(0, 2 * np.pi)
    offset = rng.uniform(*cfg["offset_diam"]) * diameter
    centre = (
        t + s * rng.uniform(*cfg["distance_diam"]) * diameter + offset * (np.cos(phi) * a + np.sin(phi) * b)
    )
    side = rng.uniform(*cfg["size_diam"]) * diameter
    size = (side, side * rng.uniform(0.4, 1.0), 0.01 * diameter)
    R = look_rotation(s, rng)
    return [
        PropSpec(
            "shadow_caster",
            "panel",
            size,
            Pose.from_arrays(R, centre),
            "dark_metal",
            int(rng.integers(2**31)),
        )
    ]


def _sample_background(
    rng: np.random.Generator,
    cfg: dict[str, Any],
    K: np.ndarray,
    camera: CameraSpec,
    z_target: float,
    radius_px: float,
) -> tuple[BackgroundSpec, list[PropSpec]]:
    kind = _choice(rng, cfg["probs"])
    bg_seed = int(rng.integers(2**31))
    params: dict[str, Any] = {}
    clutter: list[PropSpec] = []
    if kind == "earth":
        centre_dir = random_direction_in_cone(rng, np.array([0.0, 0.0, 1.0]), np.deg2rad(50))
        params = {
            "centre_dir": [float(x) for x in centre_dir],
            "angular_radius_deg": float(rng.uniform(25, 60)),
            "albedo": 0.3,
        }
    elif kind == "cluttered":
        n = int(rng.integers(cfg["clutter_count"][0], cfg["clutter_count"][1] + 1))
        f = 0.5 * (K[0, 0] + K[1, 1])
        for _ in range(n):
            depth = z_target * rng.uniform(*cfg["clutter_depth_factor"])
            u = rng.uniform(0, camera.width - 1)
            v = rng.uniform(0, camera.height - 1)
            half = rng.uniform(0.6, 2.0) * radius_px * depth / f
            shape = CLUTTER_SHAPES[int(rng.integers(len(CLUTTER_SHAPES)))]
            clutter.append(_prop(rng, "clutter", shape, backproject(K, u, v, depth), half))
    return BackgroundSpec(kind, bg_seed, params), clutter


def _sample_occluders(
    rng: np.random.Generator,
    cfg: dict[str, Any],
    K: np.ndarray,
    camera: CameraSpec,
    centre_px: tuple[float, float],
    z_target: float,
    radius_px: float,
) -> tuple[str, list[PropSpec]]:
    """Place non-target objects in front of the target so the requested occlusion group is likely."""
    group = _choice(rng, cfg["group_probs"])
    f = 0.5 * (K[0, 0] + K[1, 1])
    if group == "none":
        if rng.uniform() >= cfg["distractor_prob"]:
            return group, []
        offset_range = (1.8, 3.0)
    else:
        offset_range = OCCLUSION_OFFSETS[group]
    depth = z_target * rng.uniform(*cfg["depth_frac"])
    phi = rng.uniform(0, 2 * np.pi)
    offset = rng.uniform(*offset_range) * radius_px
    u = centre_px[0] + offset * np.cos(phi)
    v = centre_px[1] + offset * np.sin(phi)
    half = rng.uniform(*cfg["size_rel"]) * radius_px * depth / f
    shape = OCCLUDER_SHAPES[int(rng.integers(len(OCCLUDER_SHAPES)))]
    return group, [_prop(rng, "occluder", shape, backproject(K, u, v, depth), half)]


def _prop(rng: np.random.Generator, role: str, shape: str, centre: np.ndarray, half: float) -> PropSpec:
    """A prop of projected half-size `half` (metres at its depth) with a random orientation."""
    aspect = {
        "panel": (2.0, 2.0 * rng.uniform(0.4, 1.0), 0.04),
        "box": (2.0, 2.0 * rng.uniform(0.5, 1.0), 2.0 * rng.uniform(0.5, 1.0)),
        "rod": (2.0, 0.12, 0.12),
        "debris": (2.0, 2.0 * rng.uniform(0.3, 0.8), 2.0 * rng.uniform(0.2, 0.6)),
        "arm": (2.0, 0.25, 0.25),
        "truss": (2.0, 0.6, 0.6),
    }[shape]
    size = tuple(float(a * half) for a in aspect)
    R = random_rotation(rng) if shape != "panel" else look_rotation(random_unit_vector(rng), rng)
    material = PROP_MATERIALS[int(rng.integers(len(PROP_MATERIALS)))]
    return PropSpec(role, shape, size, Pose.from_arrays(R, centre), material, int(rng.integers(2**31)))
