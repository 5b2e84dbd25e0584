"""The bundled fleet beside the spacecraft: four real classes of target, built from primitives in metres at
their real proportions, then normalised as every target is (scgen.scenes.model.normalise_parts).

- `cubesat`: a 6U CubeSat (10 x 22.6 x 36.6 cm) with two deployed wings of unequal panel count, a camera,
  a patch antenna and a UHF whip: small, boxy, its finishes bare aluminium rails and cells.
- `smallsat`: a small satellite in the spirit of SPEED's Tango: a gold-foil bus under one top solar panel
  and five antennas of different lengths and directions, so that no turn maps it onto itself.
- `geosat`: a GEO communication satellite: a 2 x 1.8 x 3 m bus, two long solar arrays on yokes (four
  panels a side) and two deployed reflectors of different sizes, 15 m tip to tip.
- `upper_stage`: a spent upper stage (debris): a 4 m body of revolution, tank, skirt, adapter and engine
  bell, finished alike all round, so it looks the same turned about its axis by any angle: BOP's
  `symmetries_continuous` in its models_info.

Each is (material, mesh) parts of the six spacecraft materials (scgen.scenes.materials), which the finish
variation (`[finish]`) varies per sample as it does the spacecraft's.
"""

from __future__ import annotations

import numpy as np
import trimesh

from scgen.assets.primitives import Part, box, cylinder, dish, nozzle, revolve
from scgen.scenes.model import DEFAULT_DIAMETER_M, TargetModel, normalise_parts

# a body of revolution about the object frame's z axis, through its origin: the upper stage's (BOP: the
# axis, and a point on it in mm)
Z_AXIS_SYMMETRY = {"symmetries_continuous": [{"axis": [0.0, 0.0, 1.0], "offset": [0.0, 0.0, 0.0]}]}


def _panel(centre, extents, cells: str = "solar_cell") -> list[Part]:
    """A solar panel: a cell face (subdivided: the fine grid of real cells) on a dark backing, the cells
    facing the +z side of its thinnest extent."""
    extents = np.asarray(extents, dtype=np.float64)
    thin = int(np.argmin(extents))
    offset = np.zeros(3)
    offset[thin] = extents[thin] * 0.25
    face = trimesh.creation.box(extents=extents * np.where(np.arange(3) == thin, 0.5, 1.0))
    face.apply_translation(np.asarray(centre) + offset)
    back_extents = extents * np.where(np.arange(3) == thin, 0.5, 1.02)
    return [(cells, face.subdivide()), box(back_extents, np.asarray(centre) - offset, "dark_metal")]


def _turned(part: Part, axis_to: tuple[float, float, float], at) -> Part:
    """`part` (built about the origin, facing +z) turned to face `axis_to` and moved to `at`."""
    material, mesh = part
    mesh = mesh.copy()
    mesh.apply_transform(trimesh.geometry.align_vectors([0, 0, 1], axis_to))
    mesh.apply_translation(at)
    return material, mesh


def cubesat_parts() -> list[Part]:
    """A 6U CubeSat: x 22.6 cm, y 10 cm, z 36.6 cm, wings deployed from the -y face's long edges."""
    sx, sy, sz = 0.226, 0.100, 0.366
    parts = [box([sx - 0.012, sy - 0.012, sz - 0.01], [0, 0, 0], "dark_metal")]  # the structure's faces
    for x in (-1, 1):  # the four aluminium rails along z
        for y in (-1, 1):
            parts.append(box([0.0085, 0.0085, sz], [x * (sx / 2 - 0.00425), y * (sy / 2 - 0.00425), 0],
                             "brushed_metal"))  # fmt: skip
    parts += _panel([0, sy / 2 - 0.002, 0.02], [0.2, 0.006, 0.3])  # body-mounted cells on +y
    for k in range(2):  # the +x wing: two panels
        parts += _panel([sx / 2 + 0.105 + 0.2 * k, -sy / 2, 0.0], [0.2, 0.004, 0.34])
    parts += _panel([-(sx / 2 + 0.105), -sy / 2, 0.0], [0.2, 0.004, 0.34])  # the -x wing: one panel
    parts.append(
        cylinder([0.05, 0.03, sz / 2], [0.05, 0.03, sz / 2 + 0.025], 0.018, "dark_metal", 24)
    )  # lens
    parts.append(box([0.06, 0.06, 0.004], [-0.06, -0.015, sz / 2 + 0.002], "white_paint"))  # patch antenna
    parts.append(cylinder([-sx / 2, 0.03, -sz / 2 + 0.01], [-sx / 2 - 0.005, 0.03, -sz / 2 - 0.17], 0.0015,
                          "brushed_metal", 6))  # fmt: skip  # the UHF whip
    return parts


def smallsat_parts() -> list[Part]:
    """A Tango-like small satellite: an 80 x 75 x 30 cm gold-foil bus, one top panel, five antennas."""
    parts = [
        box([0.80, 0.75, 0.30], [0, 0, 0], "mli_gold"),
        box([0.70, 0.02, 0.22], [0.0, 0.38, -0.02], "white_paint"),  # radiator on +y
        box([0.12, 0.12, 0.04], [-0.25, -0.2, -0.17], "brushed_metal"),  # S-band patch, underneath
    ]
    parts += _panel([0.0, 0.0, 0.16], [0.88, 0.78, 0.02])  # the top panel, wider than the bus
    antennas = (  # (foot on the bus, direction, length): no two alike
        ([0.40, 0.30, 0.10], [1.0, 0.3, 0.6], 0.36),
        ([0.40, -0.30, -0.12], [0.8, -0.4, -0.5], 0.22),
        ([-0.40, 0.10, 0.12], [-1.0, 0.0, 0.9], 0.48),
        ([-0.35, -0.375, -0.10], [-0.3, -1.0, -0.2], 0.28),
        ([0.10, 0.375, -0.15], [0.2, 0.7, -1.0], 0.16),
    )
    for foot, direction, length in antennas:
        d = np.asarray(direction) / np.linalg.norm(direction)
        tip = np.asarray(foot) + length * d
        parts.append(cylinder(foot, tip, 0.006, "brushed_metal", 8))
        parts.append(box([0.025, 0.025, 0.025], tip, "dark_metal"))
    parts.append(cylinder([0.25, -0.2, 0.17], [0.25, -0.2, 0.2], 0.04, "white_paint", 24))  # GPS patch
    return parts


def geosat_parts() -> list[Part]:
    """A GEO communication satellite: bus 2 x 1.8 x 3 m, arrays along +-y, reflectors on +-x."""
    parts = [
        box([2.0, 1.8, 3.0], [0, 0, 0], "mli_gold"),
        box([2.02, 1.2, 2.4], [0, 0, 0.1], "white_paint"),  # the +-y radiator panels
        box([1.6, 1.4, 0.04], [0, 0, 1.52], "mli_silver"),  # the earth deck
    ]
    for side in (-1, 1):  # yokes and four panels a side
        parts.append(cylinder([0, side * 0.9, 0.2], [0, side * 2.0, 0.2], 0.05, "brushed_metal", 12))
        for k in range(4):
            parts += _panel([0, side * (2.05 + 1.3 * k + 0.65), 0.2], [2.4, 1.26, 0.04])
    for side, radius, tilt in ((1, 1.15, 0.35), (-1, 0.9, -0.2)):  # east and west reflectors, unalike
        centre = np.array([side * 1.6, 0.1 * side, 0.6])
        axis = (side * np.cos(tilt), 0.0, np.sin(abs(tilt)))
        parts.append(_turned(dish([0, 0, 0], radius, 0.25 * radius, "white_paint"), axis, centre))
        parts.append(cylinder([side * 1.0, 0, 1.3], centre + [0, 0, 0.2], 0.04, "brushed_metal", 8))  # arm
        parts.append(box([0.25, 0.25, 0.35], [side * 0.75, 0.3 * side, 1.7], "mli_silver"))  # feed horn
    parts.append(dish([0.4, -0.4, 1.55], 0.35, 0.08, "white_paint"))  # a small dish on the earth deck
    parts.append(nozzle([0, 0, -1.5], 0.25, 0.5, "dark_metal"))  # apogee engine
    return parts


def _revolved(profile: np.ndarray, material: str, sections: int = 64) -> Part:
    """A body of revolution about z from its (radius, z) profile."""
    return material, revolve(profile, sections=sections)


def upper_stage_parts() -> list[Part]:
    """A spent upper stage, 4 m long and 2.6 m across: every part a body of revolution about z."""
    tank = np.array([[0.0, 1.6], [0.6, 1.55], [1.0, 1.4], [1.25, 1.15], [1.3, 0.9], [1.3, -1.0],
                     [1.2, -1.3], [0.9, -1.5], [0.0, -1.55]])  # fmt: skip
    skirt = np.array([[1.3, -0.9], [1.3, -1.9], [1.28, -1.9], [1.28, -0.9]])
    adapter = np.array([[1.3, 1.2], [0.8, 2.0], [0.78, 2.0], [1.28, 1.2]])
    band = np.array([[1.305, 0.2], [1.305, -0.3], [1.3, -0.3], [1.3, 0.2]])
    parts = [
        _revolved(tank, "white_paint"),
        _revolved(skirt, "brushed_metal"),
        _revolved(adapter, "dark_metal"),
        _revolved(band, "mli_silver"),
    ]
    material, bell = nozzle([0, 0, -1.5], 0.55, 1.0, "dark_metal")
    return [*parts, (material, bell)]


# name: the model's parts and its BOP symmetries (models_info.json)
FLEET = {
    "cubesat": (cubesat_parts, {}),
    "smallsat": (smallsat_parts, {}),
    "geosat": (geosat_parts, {}),
    "upper_stage": (upper_stage_parts, Z_AXIS_SYMMETRY),
}


def build_fleet_model(name: str) -> TargetModel:
    """Fleet model `name` (FLEET), normalised, with its symmetries."""
    parts, symmetries = FLEET[name]
    model = normalise_parts(parts(), DEFAULT_DIAMETER_M, name=name)
    model.symmetries = symmetries
    return model
