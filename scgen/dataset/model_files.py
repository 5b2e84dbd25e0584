"""The target's BOP model files: models/ (parts.glb, the PLY, models_info.json) and models_eval/ (the PLY
densified for bop_toolkit's error functions)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import trimesh

from scgen.io import bop
from scgen.io.atomic import atomic_write_bytes, atomic_write_text
from scgen.scenes.materials import MATERIALS
from scgen.scenes.model import PARTS_FILE, TargetModel

EVAL_MAX_EDGE_FRAC = 0.015  # models_eval: no edge longer than this fraction of the diameter


def write_model_dir(model: TargetModel, out: Path, obj_id: int) -> None:
    """Write parts.glb (metres, named materials), the BOP PLY (`bop_ply`) and models_info.json."""
    out.mkdir(parents=True, exist_ok=True)
    scene = trimesh.Scene()
    for k, (material, mesh) in enumerate(model.parts):
        m = mesh.copy()
        m.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(name=material))
        scene.add_geometry(m, geom_name=f"{material}.{k:03d}")
    scene.export(str(out / PARTS_FILE))
    atomic_write_bytes(out / bop.model_file(obj_id), bop_ply(model.parts))
    write_models_info(model, out, obj_id)


def write_eval_model_dir(model: TargetModel, out: Path, obj_id: int) -> None:
    """Write BOP's models_eval: the PLY of `eval_parts` and the same models_info.json as models/.

    bop_toolkit's error functions (ADD, MSSD, MSPD, ...) take the vertices of this model as the object's
    point set, so it must sample the surface densely, not only at the CAD's corners.
    """
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out / bop.model_file(obj_id), bop_ply(eval_parts(model)))
    write_models_info(model, out, obj_id)


def eval_parts(
    model: TargetModel, max_edge_frac: float = EVAL_MAX_EDGE_FRAC
) -> list[tuple[str, trimesh.Trimesh]]:
    """The parts with every edge bisected until none is longer than `max_edge_frac` diameters.

    The faces are kept (split edges share their midpoint, so no cracks open) and every surface point
    ends up within 0.58 max edge of a vertex; vertices only get denser where the CAD was coarse.
    """
    out = []
    for material, mesh in model.parts:
        v, f = trimesh.remesh.subdivide_to_size(
            mesh.vertices, mesh.faces, max_edge_frac * model.diameter, max_iter=30
        )
        out.append((material, trimesh.Trimesh(v, f, process=False)))
    return out


def bop_ply(parts: list[tuple[str, trimesh.Trimesh]]) -> bytes:
    """The parts as one binary BOP PLY: millimetres, a colour per material, angle-weighted vertex normals
    (nx, ny, nz: what bop_toolkit's phong renderer needs, as BOP's own models carry them)."""
    coloured = []
    for material, mesh in parts:
        m = trimesh.Trimesh(mesh.vertices * bop.MM_PER_M, mesh.faces, process=False)
        m.visual.vertex_colors = np.tile([*MATERIALS[material].ply_colour, 255], (len(m.vertices), 1))
        coloured.append(m)
    return trimesh.exchange.ply.export_ply(
        trimesh.util.concatenate(coloured), encoding="binary", vertex_normal=True
    )


def write_models_info(model: TargetModel, out: Path, obj_id: int) -> None:
    """models_info.json: the model's box, diameter and symmetries (BOP's fields, where it has any), the
    same for models/ and models_eval/."""
    info = {str(obj_id): {**bop.models_info_entry(model.mesh.bounds, model.diameter), **model.symmetries}}
    atomic_write_text(out / bop.MODELS_INFO_FILE, json.dumps(info, indent=2) + "\n")
