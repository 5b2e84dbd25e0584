"""Build the bundled spacecraft from primitives and write it in the BOP model layout.

A box bus with differently finished faces, two solar wings on thin booms (of unequal length
and panel count), an off-centre parabolic dish on a tripod, thrusters and a main nozzle, and
thin struts: weak texture, thin structures and near-symmetry, but no exact symmetry, so every
pose is unique. `python -m scgen.assets.build` (`make assets`) writes it to `scgen/assets/spacecraft`,
package data, with the rest of the bundled fleet.
"""

from __future__ import annotations

import numpy as np
import trimesh

from scgen.assets.primitives import Part, box, cylinder, dish, nozzle
from scgen.scenes.model import TargetModel, normalise_parts


def _wing(side: int, n_panels: int, boom: float, material_cells: str) -> list[Part]:
    """A boom along +-y with `n_panels` solar panels (cells on the front, dark back, thin frame)."""
    parts = [cylinder([0, side * 0.45, 0.05], [0, side * (0.45 + boom), 0.05], 0.025, "brushed_metal")]
    y0 = 0.45 + boom
    for k in range(n_panels):
        yc = side * (y0 + 0.36 * k + 0.18)
        # segmented cell face: a grid of cells gives the fine texture of real arrays
        cells = trimesh.creation.box(extents=[0.62, 0.33, 0.012])
        cells.apply_translation([0, yc, 0.05])
        parts.append((material_cells, cells.subdivide().subdivide()))
        parts.append(box([0.64, 0.345, 0.006], [0, yc, 0.041], "dark_metal"))
    return parts


def build_parts() -> list[Part]:
    """The spacecraft as (material, mesh) parts in arbitrary units, before normalisation."""
    parts: list[Part] = [
        box([0.8, 0.9, 1.0], [0, 0, 0], "mli_gold"),  # bus body wrapped in gold MLI
        box([0.81, 0.6, 0.7], [0.0, 0.05, 0.0], "mli_silver"),  # silver MLI patch on +-x
        box([0.7, 0.91, 0.5], [0.02, 0, -0.15], "white_paint"),  # radiator band on +-y
        box([0.72, 0.82, 0.02], [0, 0, 0.51], "white_paint"),  # top deck
        box([0.2, 0.3, 0.12], [0.22, -0.25, 0.57], "brushed_metal"),  # star tracker housing
    ]
    parts += _wing(+1, 3, 0.35, "solar_cell")
    parts += _wing(-1, 2, 0.55, "solar_cell")
    dish_c = np.array([-0.12, 0.18, 0.85])
    parts.append(dish(dish_c, 0.36, 0.12, "white_paint"))
    for a in (0.0, 2.1, 4.2):  # tripod from the deck to the dish
        foot = np.array([dish_c[0] + 0.2 * np.cos(a), dish_c[1] + 0.2 * np.sin(a), 0.52])
        parts.append(cylinder(foot, dish_c + [0, 0, 0.01], 0.012, "brushed_metal", 8))
    parts.append(cylinder(dish_c + [0, 0, 0.02], dish_c + [0, 0, 0.3], 0.008, "brushed_metal", 8))  # feed
    parts.append(box([0.06, 0.06, 0.05], dish_c + [0, 0, 0.31], "dark_metal"))
    parts.append(nozzle([0.05, -0.05, -0.5], 0.14, 0.28, "dark_metal"))
    for x, y in ((0.36, 0.41), (-0.36, 0.41), (0.36, -0.41), (-0.3, -0.41)):  # RCS thrusters
        parts.append(nozzle([x, y, -0.5], 0.04, 0.08, "brushed_metal"))
    parts.append(
        cylinder([0.4, -0.3, 0.3], [0.75, -0.3, 0.55], 0.01, "brushed_metal", 8)
    )  # magnetometer boom
    parts.append(box([0.06, 0.06, 0.06], [0.75, -0.3, 0.55], "mli_silver"))
    return parts


def build_spacecraft() -> TargetModel:
    """The bundled spacecraft, normalised (its parts.glb is this, written once)."""
    return normalise_parts(build_parts(), diameter_m=0.2, name="spacecraft")
