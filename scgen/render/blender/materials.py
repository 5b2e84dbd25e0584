"""The six spacecraft material classes as Cycles node trees, and the probe material of the aux render.

Base parameters come from the registry scgen.scenes.materials, shared with the Mitsuba backend.
Details scale with the model's diameter, so any user model gets the same look: MLI foil gets a
crinkled normal (bumped fractal noise), solar cells a box-projected grid of cells and busbars.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any

import numpy as np

from scgen.scenes.materials import BUSBAR_COLOUR, CELLS_PER_SIZE, MATERIALS, Material

CRINKLES_PER_DIAMETER = 30.0  # foil wrinkles across the model


def build_materials(bpy: ModuleType, diameter: float) -> dict[str, Any]:
    """One bpy material per class in scgen.scenes.materials.MATERIALS, sized for a model of `diameter` m."""
    return {name: new_material(bpy, name, material, diameter) for name, material in MATERIALS.items()}


def probe_material(bpy: ModuleType) -> Any:
    """White diffuse + translucent: lit from either side, the aux value is |n.s| x sun visibility."""
    mat = bpy.data.materials.new("scgen_probe")
    nodes, links = _clear(mat)
    add = nodes.new("ShaderNodeAddShader")
    for k, kind in enumerate(("ShaderNodeBsdfDiffuse", "ShaderNodeBsdfTranslucent")):
        bsdf = nodes.new(kind)
        bsdf.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        links.new(bsdf.outputs[0], add.inputs[k])
    links.new(add.outputs[0], nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    return mat


def _clear(mat: Any) -> tuple[Any, Any]:
    nodes = mat.node_tree.nodes
    for node in list(nodes):
        nodes.remove(node)
    return nodes, mat.node_tree.links


def new_material(bpy: ModuleType, name: str, finish: Material, diameter: float) -> Any:
    """A Cycles material of `finish`'s class (its detail nodes), with `finish`'s values (set_finish)."""
    mat = bpy.data.materials.new(name)
    nodes, links = _clear(mat)
    bsdf = nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.name = "bsdf"
    links.new(bsdf.outputs[0], nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    coords = nodes.new("ShaderNodeTexCoord").outputs["Object"]
    if finish.detail == "crinkle":
        noise = nodes.new("ShaderNodeTexNoise")
        noise.inputs["Scale"].default_value = CRINKLES_PER_DIAMETER / diameter
        noise.inputs["Detail"].default_value = 2.0
        bump = nodes.new("ShaderNodeBump")
        bump.name = "bump"
        bump.inputs["Strength"].default_value = 0.6
        links.new(coords, noise.inputs["Vector"])
        links.new(noise.outputs["Fac"], bump.inputs["Height"])
        links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
    elif finish.detail == "cells":
        scale = nodes.new("ShaderNodeVectorMath")
        scale.operation = "SCALE"
        scale.inputs["Scale"].default_value = CELLS_PER_SIZE / diameter
        tex = nodes.new("ShaderNodeTexImage")
        tex.image, tex.projection, tex.projection_blend = _cell_image(bpy), "BOX", 0.2
        ramp = nodes.new("ShaderNodeValToRGB")
        ramp.name = "ramp"
        ramp.color_ramp.elements[1].color = (*BUSBAR_COLOUR, 1.0)
        links.new(coords, scale.inputs[0])
        links.new(scale.outputs["Vector"], tex.inputs["Vector"])
        links.new(tex.outputs["Color"], ramp.inputs["Fac"])
        links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])
        links.new(tex.outputs["Color"], bsdf.inputs["Metallic"])  # busbars and gaps are metal
    set_finish(mat, finish, diameter)
    return mat


def set_finish(mat: Any, finish: Material, diameter: float) -> None:
    """Set a material made by new_material (of the same detail) to `finish`'s values."""
    nodes = mat.node_tree.nodes
    bsdf = nodes["bsdf"]
    bsdf.inputs["Base Color"].default_value = (*finish.base, 1.0)
    bsdf.inputs["Roughness"].default_value = finish.roughness
    bsdf.inputs["Metallic"].default_value = finish.metallic
    bsdf.inputs["Specular IOR Level"].default_value = finish.specular
    bsdf.inputs["Anisotropic"].default_value = finish.anisotropic
    if finish.detail == "crinkle":
        nodes["bump"].inputs["Distance"].default_value = 0.02 * diameter * finish.crinkle
    elif finish.detail == "cells":
        nodes["ramp"].color_ramp.elements[0].color = (*finish.base, 1.0)


def cell_pattern(size: int = 16) -> np.ndarray:
    """One solar cell as a size x size mask: 1 on the cell gap (first row/column) and two busbars."""
    mask = np.zeros((size, size), np.float32)
    mask[0, :] = mask[:, 0] = 1.0
    mask[:, size // 3] = mask[:, 2 * size // 3] = 0.7
    return mask


def _cell_image(bpy: ModuleType) -> Any:
    """The solar-cell mask image, made on first use and shared by every solar-cell material."""
    img = bpy.data.images.get("scgen_cells")
    if img is not None:
        return img
    mask = cell_pattern()
    img = bpy.data.images.new("scgen_cells", mask.shape[1], mask.shape[0], alpha=False, float_buffer=True)
    img.colorspace_settings.name = "Non-Color"
    rgba = np.stack([mask, mask, mask, np.ones_like(mask)], axis=-1)[::-1]  # Blender rows run bottom-up
    img.pixels.foreach_set(rgba.ravel())
    return img
