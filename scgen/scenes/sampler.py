"""Sample the SceneSpec of sample `index` of `seed`: pure, deterministic, renderer-free."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from scgen.scenes.attitude import sample_attitude
from scgen.scenes.config.camera import CameraSettings
from scgen.scenes.config.scene import USER_BACKGROUND, distance_range_m
from scgen.scenes.finish import sample_finish
from scgen.scenes.geometry import (
    backproject,
    orthonormal_basis,
    random_direction_in_cone,
    unit_sphere_hits,
)
from scgen.scenes.imaging import sample_imaging
from scgen.scenes.materials import PROP_MATERIALS
from scgen.scenes.placement import Blank, place_caster, place_occluder
from scgen.scenes.props import bounding_radius
from scgen.scenes.rng import choice, factor_rng
from scgen.scenes.silhouette import CameraView, TargetShape, camera_view, sun_view
from scgen.scenes.sky import BODY_OF_KIND, sky_params
from scgen.scenes.spec import BackgroundSpec, CameraSpec, PlacedObject, Pose, PropSpec, SceneSpec, SunSpec

OCCLUDER_SHAPES = ("panel", "box", "rod", "debris", "arm")
CASTER_SHAPES = ("panel", "box", "truss", "arm")
CLUTTER_SHAPES = ("truss", "panel", "box", "debris", "arm")
BODY_MIN_LIT = 0.08  # share of the frame an Earth or Moon background must show as lit day side
BODY_TRIES = 32
OBJECT_TRIES = 64  # placements an `[[objects]]` instance draws until it clears every object before it


@dataclass(frozen=True)
class ObjectDraw:
    """What the sampler needs of one `[[objects]]` entry: its obj_id, its model's shape and the entry."""

    obj_id: int
    shape: TargetShape
    entry: dict[str, Any]


def sample_scene(
    seed: int, index: int, cfg: dict[str, Any], shape: TargetShape, objects: Sequence[ObjectDraw] = ()
) -> SceneSpec:
    """The SceneSpec of one sample; depends only on (seed, index, cfg, the objects' geometry).

    `shape` is the target's geometry (scgen.Generator builds it from the model): its diameter sets the
    distance range, its silhouette aims the occluders and shadow casters. `objects`: the config's
    `[[objects]]` entries, placed last (from their own stream), so the target's draws are what they are
    without them.
    """
    diameter_m = shape.diameter
    camera = CameraSpec.from_config(cfg["camera"])
    camera_settings = CameraSettings.from_table(cfg["camera"])
    K = camera.K_mat
    f = camera.focal

    # the camera-target distance |t| is uniform over its range (the factor the robustness table bins)
    d_min, d_max = distance_range_m(cfg, diameter_m)
    distance = float(factor_rng(seed, index, "distance").uniform(d_min, d_max))
    radius_px = f * 0.5 * diameter_m / distance

    t = _in_frame(factor_rng(seed, index, "position"), cfg, camera, radius_px, distance)
    R, cone = sample_attitude(factor_rng(seed, index, "pose"), cfg["pose"], t)
    target_cam = shape.in_camera(R, t)
    view = camera_view(K, camera.width, camera.height, target_cam)

    sun = _sample_sun(factor_rng(seed, index, "illumination"), cfg["illumination"], t)
    sun_dir = np.asarray(sun.direction)
    background, clutter = _sample_sky_side(seed, index, cfg["background"], camera, t, shape.radius, radius_px,
                                           sun_dir)  # fmt: skip
    occ_group, occluders = _sample_occluders(
        factor_rng(seed, index, "occluders"), cfg["occluders"], view, t, shape.radius
    )
    caster = _sample_shadow_caster(
        factor_rng(seed, index, "shadow"), cfg["shadow"], view, t, sun_dir, shape, target_cam
    )
    near_view = _sample_sun_near_view(factor_rng(seed, index, "sun_view"), cfg["illumination"], camera)
    if near_view is not None and not caster:  # a caster is placed for the first sun: it keeps it
        sun = replace(sun, direction=tuple(float(x) for x in near_view))
        background, clutter = _sample_sky_side(seed, index, cfg["background"], camera, t, shape.radius,
                                               radius_px, near_view)  # fmt: skip
    props = tuple(occluders + caster + clutter)
    return SceneSpec(
        seed=int(seed),
        index=int(index),
        camera=camera,
        target=Pose.from_arrays(R, t),
        distance_m=distance,
        sun=sun,
        background=background,
        props=props,
        requested_occlusion=occ_group,
        shadow_caster=bool(caster),
        imaging=sample_imaging(factor_rng(seed, index, "camera"), camera_settings),
        finish=sample_finish(factor_rng(seed, index, "finish"), cfg["finish"]),
        cone=cone,
        objects=_sample_objects(
            factor_rng(seed, index, "objects"),
            cfg,
            camera,
            objects,
            [(t, shape.radius)] + [_prop_ball(p) for p in props],
        ),  # fmt: skip
    )


def _in_frame(
    rng: np.random.Generator, cfg: dict[str, Any], camera: CameraSpec, radius_px: float, distance: float
) -> np.ndarray:
    """An object's centre at `distance` from the camera, its image uniform over the frame at least
    `position.inside_radius_frac` of its projected radius `radius_px` inside (at most 0.45 of the frame's
    shorter side)."""
    margin = min(cfg["position"]["inside_radius_frac"] * radius_px, 0.45 * min(camera.width, camera.height))
    u = rng.uniform(margin, camera.width - 1 - margin)
    v = rng.uniform(margin, camera.height - 1 - margin)
    ray = backproject(camera.K_mat, u, v, 1.0)
    return distance * ray / np.linalg.norm(ray)


def _prop_ball(prop: PropSpec) -> tuple[np.ndarray, float]:
    return prop.pose.t_vec, bounding_radius(prop.shape, np.asarray(prop.size))


def _sample_objects(
    rng: np.random.Generator, cfg: dict[str, Any], camera: CameraSpec, objects: Sequence[ObjectDraw],
    taken: list[tuple[np.ndarray, float]],
) -> tuple[PlacedObject, ...]:  # fmt: skip
    """Every `[[objects]]` instance, in entry order: its distance uniform over the entry's range, its centre
    in the frame as the target's is, its attitude from the entry's pose table. An instance's bounding ball
    clears every ball before it (the target's, the props', the instances placed), redrawn up to
    OBJECT_TRIES times; if none clears, the draw that comes closest is kept (ranges that leave no room)."""
    placed = []
    for obj in objects:
        entry = obj.entry
        d_min, d_max = distance_range_m(cfg, obj.shape.diameter, entry["distance"])
        for _ in range(entry["count"]):
            best: tuple[float, np.ndarray] | None = None
            for _ in range(OBJECT_TRIES):
                distance = rng.uniform(d_min, d_max)
                radius_px = camera.focal * 0.5 * obj.shape.diameter / distance
                t = _in_frame(rng, cfg, camera, radius_px, distance)
                clearance = min(np.linalg.norm(t - c) - (r + obj.shape.radius) for c, r in taken)
                if best is None or clearance > best[0]:
                    best = (clearance, t)
                if clearance > 0:
                    break
            assert best is not None
            t = best[1]
            R, _ = sample_attitude(rng, entry["pose"], t)
            taken.append((t, obj.shape.radius))
            placed.append(PlacedObject(obj.obj_id, Pose.from_arrays(R, t)))
    return tuple(placed)


def _sample_sun(rng: np.random.Generator, cfg: dict[str, Any], t: np.ndarray) -> SunSpec:
    level = choice(rng, cfg["probs"])
    to_camera = -t / np.linalg.norm(t)
    direction = random_direction_in_cone(rng, to_camera, np.deg2rad(cfg["max_phase_deg"]))
    irradiance = cfg["solar_irradiance"] * cfg["multipliers"][level]
    return SunSpec(tuple(float(x) for x in direction), level, float(irradiance))


def _sample_sky_side(
    seed: int, index: int, cfg: dict[str, Any], camera: CameraSpec, t: np.ndarray, radius: float,
    radius_px: float, sun_dir: np.ndarray,
) -> tuple[BackgroundSpec, list[PropSpec]]:  # fmt: skip
    """The background, its clutter and its sky under this sun, from the background and sky streams (the
    clutter does not depend on the sun, the Earth's placement and the sky do)."""
    background, clutter = _sample_background(
        factor_rng(seed, index, "background"), cfg, camera, t, radius, radius_px, sun_dir
    )
    background.params.update(sky_params(background.kind, cfg, factor_rng(seed, index, "sky"), sun_dir))
    return background, clutter


def _sample_sun_near_view(
    rng: np.random.Generator, cfg: dict[str, Any], camera: CameraSpec
) -> np.ndarray | None:
    """With probability sun_near_view.prob, a direction towards the sun whose pinhole image falls
    uniformly over the frame widened by `margin` of its size on every side; else None."""
    near = cfg["sun_near_view"]
    if rng.uniform() >= near["prob"]:
        return None
    m = near["margin"]
    u = rng.uniform(-m, 1 + m) * camera.width - 0.5
    v = rng.uniform(-m, 1 + m) * camera.height - 0.5
    ray = backproject(camera.K_mat, u, v, 1.0)
    return ray / np.linalg.norm(ray)


def _sample_shadow_caster(
    rng: np.random.Generator, cfg: dict[str, Any], view: CameraView | None, t: np.ndarray,
    sun_dir: np.ndarray, shape: TargetShape, target_cam: list[np.ndarray],
) -> list[PropSpec]:  # fmt: skip
    """With probability caster_prob, a prop on the sun side aimed to shade part of the target."""
    if rng.uniform() >= cfg["caster_prob"] or view is None:
        return []
    sun = sun_view(np.stack(orthonormal_basis(sun_dir)), t, shape.radius, target_cam)
    blank = Blank.draw(rng, "shadow_caster", CASTER_SHAPES, PROP_MATERIALS, facing=sun_dir)
    prop = place_caster(rng, cfg, view, sun, t, sun_dir, shape.radius, shape.diameter, blank)
    return [prop] if prop is not None else []


def _sample_occluders(
    rng: np.random.Generator, cfg: dict[str, Any], view: CameraView | None, t: np.ndarray, radius: float
) -> tuple[str, list[PropSpec]]:
    """The requested occlusion group and the occluder aimed at it ('none': maybe a distractor)."""
    group = choice(rng, cfg["group_probs"])
    if view is None or (group == "none" and rng.uniform() >= cfg["distractor_prob"]):
        return group, []
    blank = Blank.draw(rng, "occluder", OCCLUDER_SHAPES, PROP_MATERIALS)
    return group, [place_occluder(rng, cfg, view, t, radius, group, blank)]


def _sample_background(
    rng: np.random.Generator, cfg: dict[str, Any], camera: CameraSpec, t: np.ndarray, radius: float,
    radius_px: float, sun_dir: np.ndarray,
) -> tuple[BackgroundSpec, list[PropSpec]]:  # fmt: skip
    kind = choice(rng, cfg["probs"])
    bg_seed = int(rng.integers(2**31))
    params: dict[str, Any] = {}
    clutter: list[PropSpec] = []
    if kind in BODY_OF_KIND:
        params = _sample_body(rng, cfg, camera, sun_dir, BODY_OF_KIND[kind])
    elif kind == USER_BACKGROUND:
        images = cfg["user_images"]
        params = {"image": images[int(rng.integers(len(images)))]}
    elif kind == "cluttered":
        n = int(rng.integers(cfg["clutter_count"][0], cfg["clutter_count"][1] + 1))
        for _ in range(n):
            blank = Blank.draw(rng, "clutter", CLUTTER_SHAPES, PROP_MATERIALS)
            depth = t[2] * rng.uniform(*cfg["clutter_depth_factor"])
            u, v = rng.uniform(0, camera.width - 1), rng.uniform(0, camera.height - 1)
            half = rng.uniform(*cfg["clutter_size_rel"]) * radius_px * depth / camera.focal
            depth = max(depth, t[2] + radius + blank.bound * half)  # wholly behind the target
            clutter.append(blank.spec(half, backproject(camera.K_mat, u, v, depth)))
    return BackgroundSpec(kind, bg_seed, params), clutter


def _sample_body(
    rng: np.random.Generator, cfg: dict[str, Any], camera: CameraSpec, sun_dir: np.ndarray, body: str
) -> dict[str, Any]:
    """The Earth's or the Moon's limb (low orbit) or disc (high orbit) in view, its part in the frame
    mostly day side (config keys `{body}_limb_prob`, `{body}_limb_radius_deg`, ...).

    The body is a unit sphere seen at angular radius rho; its centre direction makes angle theta
    with the optical axis (theta near rho puts the limb across the frame). Placements are redrawn
    (a bounded number of times, deterministically) until the frame shows enough lit surface.
    """
    K = camera.K_mat
    half_diag = np.arctan(np.hypot(0.5 * camera.width / K[0, 0], 0.5 * camera.height / K[1, 1]))
    v, u = np.mgrid[0 : camera.height : camera.height / 12, 0 : camera.width : camera.width / 16]
    rays = camera.rays(u.ravel(), v.ravel())
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    x, y = orthonormal_basis(np.array([0.0, 0.0, 1.0]))
    best: tuple[float, dict[str, Any]] = (-1.0, {})
    for _ in range(BODY_TRIES):
        limb = bool(rng.uniform() < cfg[f"{body}_limb_prob"])
        if limb:
            rho = np.deg2rad(rng.uniform(*cfg[f"{body}_limb_radius_deg"]))
            theta = rho + rng.uniform(-0.8, 0.3) * half_diag
        else:
            rho = np.deg2rad(rng.uniform(*cfg[f"{body}_disc_radius_deg"]))
            theta = rng.uniform(0.0, max(half_diag - 0.3 * rho, 0.0))
        az = rng.uniform(0, 2 * np.pi)
        centre = np.cos(theta) * np.array([0.0, 0.0, 1.0]) + np.sin(theta) * (np.cos(az) * x + np.sin(az) * y)
        params = {"centre_dir": [float(c) for c in centre], "angular_radius_deg": float(np.rad2deg(rho)),
                  "albedo": float(cfg[f"{body}_albedo"]), "limb": limb}  # fmt: skip
        score = _lit_share(rays, centre / np.sin(rho), sun_dir)
        if score >= BODY_MIN_LIT:
            return params
        best = max(best, (score, params), key=lambda b: b[0])
    return best[1]


def _lit_share(rays: np.ndarray, centre: np.ndarray, sun_dir: np.ndarray) -> float:
    """Share of the probe rays that see the unit sphere at `centre` on its day side."""
    _, normal, _, _ = unit_sphere_hits(rays, centre)
    return float(np.sum(normal @ sun_dir > 0.15) / len(rays))
