"""The material classes of the target and the props: one registry that each renderer translates.

Base parameters are those of a Principled BSDF (metals: metallic 1 with their normal-incidence
reflectance as base colour). `detail` names the procedural detail each backend adds in its own way:
crinkled MLI foil, or a grid of solar cells with busbars. `ply_colour` is the sRGB vertex colour the
BOP PLY gets, for viewers and the BOP toolkit.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Material:
    base: tuple[float, float, float]  # linear RGB
    roughness: float
    metallic: float = 0.0
    specular: float = (
        0.5  # F0 = 0.08 * specular (0.5: IOR 1.5); Cycles' "Specular IOR Level", Mitsuba's `specular`
    )
    anisotropic: float = 0.0
    detail: str = ""  # "crinkle", "cells" or ""
    ply_colour: tuple[int, int, int] = (128, 128, 128)
    crinkle: float = 1.0  # factor on the crinkle's normal strength (a per-sample finish varies it)


MATERIALS: dict[str, Material] = {
    "mli_gold": Material(
        (1.0, 0.71, 0.29), roughness=0.5, metallic=1.0, detail="crinkle", ply_colour=(212, 160, 60)
    ),
    "mli_silver": Material(
        (0.95, 0.93, 0.88), roughness=0.45, metallic=1.0, detail="crinkle", ply_colour=(200, 200, 205)
    ),
    "solar_cell": Material(
        (0.02, 0.03, 0.09), roughness=0.15, specular=0.6, detail="cells", ply_colour=(30, 40, 90)
    ),
    "white_paint": Material((0.75, 0.75, 0.72), roughness=0.6, ply_colour=(235, 235, 230)),
    "brushed_metal": Material(
        (0.91, 0.92, 0.92), roughness=0.39, metallic=1.0, anisotropic=0.5, ply_colour=(160, 160, 165)
    ),
    "dark_metal": Material((0.05, 0.05, 0.055), roughness=0.4, metallic=0.5, ply_colour=(60, 60, 65)),
}
# the classes props are drawn from, in the order the sampler indexes them (changing it changes datasets)
PROP_MATERIALS = ("white_paint", "brushed_metal", "mli_silver", "dark_metal", "mli_gold", "solar_cell")
CELLS_PER_SIZE = 40.0  # solar cells across the object (target diameter, or a prop's longest side)
BUSBAR_COLOUR = (0.6, 0.6, 0.62)


@dataclass(frozen=True)
class FinishRange:
    """How far a class's finish may vary from sample to sample (config finish.jitter scales each range
    towards the nominal value: 0 keeps it, 1 uses it whole).

    brightness: factor on the base colour, log-uniform; tint: largest relative change of each colour
    channel; roughness and metallic: absolute ranges; detail: factor on the crinkle's normal strength
    (MLI only).
    """

    brightness: tuple[float, float]
    tint: float
    roughness: tuple[float, float]
    metallic: tuple[float, float]
    detail: tuple[float, float] = (1.0, 1.0)


FINISH_RANGES: dict[str, FinishRange] = {
    "mli_gold": FinishRange((0.75, 1.1), 0.08, (0.3, 0.7), (1.0, 1.0), detail=(0.4, 1.8)),
    "mli_silver": FinishRange((0.75, 1.05), 0.05, (0.25, 0.65), (1.0, 1.0), detail=(0.4, 1.8)),
    "solar_cell": FinishRange((0.6, 1.8), 0.2, (0.08, 0.3), (0.0, 0.0)),
    "white_paint": FinishRange((0.7, 1.05), 0.05, (0.4, 0.85), (0.0, 0.0)),
    "brushed_metal": FinishRange((0.85, 1.05), 0.04, (0.25, 0.55), (1.0, 1.0)),
    "dark_metal": FinishRange((0.6, 1.8), 0.1, (0.3, 0.7), (0.2, 0.8)),
}
