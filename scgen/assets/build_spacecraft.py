"""Build the bundled spacecraft from primitives and write it in the BOP model layout.

A box bus with differently finished faces, two solar wings on thin booms (of unequal length
and panel count), an off-centre parabolic dish on a tripod, thrusters and a main nozzle, and
thin struts: weak texture, thin structures and near-symmetry, but no exact symmetry, so every
pose is unique. Run `python -m scgen.assets.build_spacecraft` (`make assets`) to regenerate
`scgen/assets/spacecraft`, package data.
"""

from __future__ import annotations

import numpy as np
import trimesh

from scgen.dataset.layout import OBJ_ID
from scgen.dataset.model_files import write_model_dir
from scgen.scenes.model import BUNDLED_MODEL_DIR, TargetModel, normalise_parts


def _box(extents, centre, material: str) -> tuple[str, trimesh.Trimesh]:
    m = trimesh.creation.box(extents=extents)
    m.apply_translation(centre)
    return material, m


def _cylinder(p0, p1, radius: float, material: str, sections: int = 16) -> tuple[str, trimesh.Trimesh]:
    return material, trimesh.creation.cylinder(radius=radius, segment=[p0, p1], sections=sections)


def _wing(side: int, n_panels: int, boom: float, material_cells: str) -> list[tuple[str, trimesh.Trimesh]]:
    """A boom along +-y with `n_panels` solar panels (cells on the front, dark back, thin frame)."""
    parts = [_cylinder([0, side * 0.45, 0.05], [0, side * (0.45 + boom), 0.05], 0.025, "brushed_metal")]
    y0 = 0.45 + boom
    for k in range(n_panels):
        yc = side * (y0 + 0.36 * k + 0.18)
        # segmented cell face: a grid of cells gives the fine texture of real arrays
        cells = trimesh.creation.box(extents=[0.62, 0.33, 0.012])
        cells.apply_translation([0, yc, 0.05])
        parts.append((material_cells, cells.subdivide().subdivide()))
        parts.append(_box([0.64, 0.345, 0.006], [0, yc, 0.041], "dark_metal"))
    return parts


def _dish(centre, radius: float, depth: float, material: str) -> tuple[str, trimesh.Trimesh]:
    """A thin parabolic reflector, opening towards +z, built by revolving its profile."""
    r = np.linspace(0.0, radius, 24)
    z = depth * (r / radius) ** 2
    inner = np.column_stack([r, z])
    outer = np.column_stack([r[::-1], z[::-1] - 0.01])
    profile = np.vstack([inner, outer])
    m = trimesh.creation.revolve(profile, sections=48)
    m.apply_translation(centre)
    return material, m


def _nozzle(centre, radius: float, length: float, material: str) -> tuple[str, trimesh.Trimesh]:
    """A bell nozzle pointing along -z."""
    s = np.linspace(0, 1, 12)
    r = radius * (0.35 + 0.65 * s**1.5)
    z = -length * s
    profile = np.vstack([np.column_stack([r, z]), np.column_stack([r[::-1] * 0.9, z[::-1]])])
    m = trimesh.creation.revolve(profile, sections=24)
    m.apply_translation(centre)
    return material, m


def build_parts() -> list[tuple[str, trimesh.Trimesh]]:
    """The spacecraft as (material, mesh) parts in arbitrary units, before normalisation."""
    parts: list[tuple[str, trimesh.Trimesh]] = [
        _box([0.8, 0.9, 1.0], [0, 0, 0], "mli_gold"),  # bus body wrapped in gold MLI
        _box([0.81, 0.6, 0.7], [0.0, 0.05, 0.0], "mli_silver"),  # silver MLI patch on +-x
        _box([0.7, 0.91, 0.5], [0.02, 0, -0.15], "white_paint"),  # radiator band on +-y
        _box([0.72, 0.82, 0.02], [0, 0, 0.51], "white_paint"),  # top deck
        _box([0.2, 0.3, 0.12], [0.22, -0.25, 0.57], "brushed_metal"),  # star tracker housing
    ]
    parts += _wing(+1, 3, 0.35, "solar_cell")
    parts += _wing(-1, 2, 0.55, "solar_cell")
    dish_c = np.array([-0.12, 0.18, 0.85])
    parts.append(_dish(dish_c, 0.36, 0.12, "white_paint"))
    for a in (0.0, 2.1, 4.2):  # tripod from the deck to the dish
        foot = np.array([dish_c[0] + 0.2 * np.cos(a), dish_c[1] + 0.2 * np.sin(a), 0.52])
        parts.append(_cylinder(foot, dish_c + [0, 0, 0.01], 0.012, "brushed_metal", 8))
    parts.append(_cylinder(dish_c + [0, 0, 0.02], dish_c + [0, 0, 0.3], 0.008, "brushed_metal", 8))  # feed
    parts.append(_box([0.06, 0.06, 0.05], dish_c + [0, 0, 0.31], "dark_metal"))
    parts.append(_nozzle([0.05, -0.05, -0.5], 0.14, 0.28, "dark_metal"))
    for x, y in ((0.36, 0.41), (-0.36, 0.41), (0.36, -0.41), (-0.3, -0.41)):  # RCS thrusters
        parts.append(_nozzle([x, y, -0.5], 0.04, 0.08, "brushed_metal"))
    parts.append(
        _cylinder([0.4, -0.3, 0.3], [0.75, -0.3, 0.55], 0.01, "brushed_metal", 8)
    )  # magnetometer boom
    parts.append(_box([0.06, 0.06, 0.06], [0.75, -0.3, 0.55], "mli_silver"))
    return parts


def build_spacecraft() -> TargetModel:
    return normalise_parts(build_parts(), diameter_m=0.2, name="spacecraft")


def main() -> None:
    model = build_spacecraft()
    write_model_dir(model, BUNDLED_MODEL_DIR, OBJ_ID)
    size = f"{len(model.mesh.faces)} triangles, diameter {model.diameter * 1000:.1f} mm"
    print(f"wrote {BUNDLED_MODEL_DIR}: {size}")


if __name__ == "__main__":
    main()
