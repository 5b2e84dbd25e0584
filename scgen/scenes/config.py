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

ILLUMINATION_LEVELS = ("weak", "normal", "strong")
BACKGROUND_KINDS = ("clean", "complex", "earth", "cluttered")
OCCLUSION_GROUPS = ("none", "slight", "moderate", "heavy")

DEFAULT_CONFIG: dict[str, Any] = {
    "camera": {
        "width": 640,
        "height": 480,
        "fx": 600.0,
        "fy": 600.0,
        "cx": None,  # None: (width - 1) / 2, the image centre under the pixel-centre convention
        "cy": None,
        "exposure_ev": 0.0,
    },
    "distance": {
        # projected diameter range (px) that sets the default distance range; range_m overrides it
        "min_px": 60.0,
        "max_px": 300.0,
        "range_m": None,
    },
    "position": {
        # the target centre stays at least this fraction of its projected radius inside the frame
        "inside_radius_frac": 0.5,
    },
    "illumination": {
        "solar_irradiance": 1361.0,  # W/m^2 at 1 AU
        "multipliers": {"weak": 0.3, "normal": 1.0, "strong": 2.5},
        "probs": {"weak": 1 / 3, "normal": 1 / 3, "strong": 1 / 3},
        # largest sun phase angle (sun direction vs. direction to the camera), degrees
        "max_phase_deg": 110.0,
    },
    "shadow": {
        "caster_prob": 0.5,
        # caster distance from the target centre and lateral offset, in target diameters
        "distance_diam": [1.0, 2.0],
        "offset_diam": [0.0, 0.45],
        "size_diam": [0.6, 1.2],
    },
    "background": {
        "probs": {"clean": 0.25, "complex": 0.25, "earth": 0.25, "cluttered": 0.25},
        "clutter_count": [2, 5],
        "clutter_depth_factor": [1.6, 4.0],
    },
    "occluders": {
        "group_probs": {"none": 0.25, "slight": 0.25, "moderate": 0.25, "heavy": 0.25},
        # occluder depth as a fraction of the target depth
        "depth_frac": [0.45, 0.8],
        # projected occluder half-size relative to the target's projected radius
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
            if not isinstance(value, dict) or set(value) - set(base[key]):
                raise ScgenError(f"config key '{name}' must map {sorted(base[key])} to numbers")
            base[key] = {k: float(value.get(k, 0.0)) for k in base[key]}
        else:
            base[key] = value


def _is_label_map(d: dict[str, Any]) -> bool:
    return all(isinstance(v, (int, float)) for v in d.values()) and set(d) <= set(
        ILLUMINATION_LEVELS + BACKGROUND_KINDS + OCCLUSION_GROUPS
    )


def load_config(
    path: str | Path | None = None,
    overrides: dict[str, Any] | None = None,
    resolution: tuple[int, int] | None = None,
) -> dict[str, Any]:
    """Defaults, then the file at `path` (TOML/YAML/JSON), `overrides`, `resolution`; validated, resolved."""
    cfg = copy.deepcopy(DEFAULT_CONFIG)
    if path is not None:
        _merge(cfg, read_config_file(Path(path)))
    if overrides:
        _merge(cfg, overrides)
    if resolution is not None:
        apply_resolution(cfg, *resolution)
    return resolve(cfg)


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
    cfg["distance"]["min_px"] *= s
    cfg["distance"]["max_px"] *= s


def read_config_file(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise ScgenError(f"config file not found: {path}")
    text = path.read_text()
    try:
        if path.suffix.lower() in (".yaml", ".yml"):
            data = yaml.safe_load(text) or {}
        elif path.suffix.lower() == ".json":
            data = json.loads(text)
        else:
            data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, yaml.YAMLError, json.JSONDecodeError) as exc:
        raise ScgenError(f"cannot parse config {path}: {str(exc).splitlines()[0]}") from exc
    if not isinstance(data, dict):
        raise ScgenError(f"config {path} must be a table of sections")
    return data


def resolve(cfg: dict[str, Any]) -> dict[str, Any]:
    """Fill derived values (principal point, distance range) and check every range; returns cfg."""
    cam = cfg["camera"]
    for key in ("width", "height"):
        if not isinstance(cam[key], int) or cam[key] <= 0:
            raise ScgenError(f"camera.{key} must be a positive integer, got {cam[key]!r}")
    if cam["fx"] <= 0 or cam["fy"] <= 0:
        raise ScgenError(f"camera focal lengths must be positive, got fx={cam['fx']} fy={cam['fy']}")
    cam["cx"] = (cam["width"] - 1) / 2 if cam["cx"] is None else float(cam["cx"])
    cam["cy"] = (cam["height"] - 1) / 2 if cam["cy"] is None else float(cam["cy"])

    dist = cfg["distance"]
    if dist["range_m"] is None:
        _check_range("distance.min_px/max_px", [dist["min_px"], dist["max_px"]], low=1.0)
    else:
        _check_range("distance.range_m", dist["range_m"], low=1e-6)

    for name in ("depth_frac", "size_rel"):
        _check_range(f"occluders.{name}", cfg["occluders"][name], low=1e-6)
    if not cfg["occluders"]["depth_frac"][1] < 1.0:
        raise ScgenError("occluders.depth_frac must stay below 1 (occluders sit in front of the target)")
    for name in ("distance_diam", "offset_diam", "size_diam"):
        _check_range(f"shadow.{name}", cfg["shadow"][name], low=0.0)
    _check_range("background.clutter_count", cfg["background"]["clutter_count"], low=0)
    _check_range("background.clutter_depth_factor", cfg["background"]["clutter_depth_factor"], low=1.0)
    _check_prob("shadow.caster_prob", cfg["shadow"]["caster_prob"])
    _check_prob("occluders.distractor_prob", cfg["occluders"]["distractor_prob"])
    if not 0 <= cfg["illumination"]["max_phase_deg"] <= 180:
        raise ScgenError("illumination.max_phase_deg must lie in [0, 180]")
    for name in ("illumination.probs", "background.probs", "occluders.group_probs"):
        section, key = name.split(".")
        _check_distribution(name, cfg[section][key])
    for level, m in cfg["illumination"]["multipliers"].items():
        if m <= 0:
            raise ScgenError(f"illumination.multipliers.{level} must be positive, got {m}")
    return cfg


def _check_range(name: str, value: Any, low: float) -> None:
    ok = (
        isinstance(value, (list, tuple))
        and len(value) == 2
        and all(isinstance(v, (int, float)) for v in value)
    )
    if not ok or not (low <= value[0] <= value[1]):
        raise ScgenError(f"{name} must be [min, max] with {low} <= min <= max, got {value!r}")


def _check_prob(name: str, p: Any) -> None:
    if not isinstance(p, (int, float)) or not 0.0 <= p <= 1.0:
        raise ScgenError(f"{name} must be a probability in [0, 1], got {p!r}")


def _check_distribution(name: str, probs: dict[str, float]) -> None:
    if any(p < 0 for p in probs.values()) or not math.isclose(sum(probs.values()), 1.0, abs_tol=1e-6):
        raise ScgenError(f"{name} must be non-negative and sum to 1, got {probs}")


def distance_range_m(cfg: dict[str, Any], diameter_m: float) -> tuple[float, float]:
    """Camera-target distance range: from range_m, or from the projected-diameter range in pixels."""
    dist = cfg["distance"]
    if dist["range_m"] is not None:
        return float(dist["range_m"][0]), float(dist["range_m"][1])
    f = 0.5 * (cfg["camera"]["fx"] + cfg["camera"]["fy"])
    return f * diameter_m / dist["max_px"], f * diameter_m / dist["min_px"]
