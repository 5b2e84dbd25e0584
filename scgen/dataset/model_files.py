"""The objects' BOP model files: models/ (parts.glb, each object's PLY, models_info.json) and models_eval/
(the PLYs densified for bop_toolkit's error functions). The target is obj_id 1 (its parts in parts.glb);
each `[[objects]]` model follows (its parts in obj_00000K_parts.glb)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import trimesh

from scgen.io import bop
from scgen.io.atomic import atomic_write_bytes, atomic_write_text
from scgen.scenes.materials import MATERIALS
from scgen.scenes.model import PARTS_FILE, TargetModel

EVAL_MAX_EDGE_FRAC = 0.015  # models_eval: no edge longer than this fraction of the diameter


def write_model_dir(models: Mapping[int, TargetModel], out: Path) -> None:
    """Write each object's parts (metres, named materials: `parts_file`), its BOP PLY (`bop_ply`) and
    models_info.json; `models` by obj_id."""
    out.mkdir(parents=True, exist_ok=True)
    for obj_id, model in models.items():
        scene = trimesh.Scene()
        for k, (material, mesh) in enumerate(model.parts):
            m = mesh.copy()
            named = trimesh.visual.material.PBRMaterial(name=material)
            m.visual = trimesh.visual.TextureVisuals(material=named)
            scene.add_geometry(m, geom_name=f"{material}.{k:03d}")
        scene.export(str(out / parts_file(obj_id)))
        atomic_write_bytes(out / bop.model_file(obj_id), bop_ply(model.parts))
    write_models_info(models, out)


def parts_file(obj_id: int) -> str:
    """The file of object `obj_id`'s parts in models/: PARTS_FILE for the target (as a bundled model's
    folder holds it), obj_00000K_parts.glb for the others."""
    return PARTS_FILE if obj_id == bop.TARGET_OBJ_ID else f"{Path(bop.model_file(obj_id)).stem}_{PARTS_FILE}"


def write_eval_model_dir(models: Mapping[int, TargetModel], out: Path) -> None:
    """Write BOP's models_eval: each object's PLY of `eval_parts` and the same models_info.json as models/.

    bop_toolkit's error functions (ADD, MSSD, MSPD, ...) take the vertices of this model as the object's
    point set, so it must sample the surface densely, not only at the CAD's corners.
    """
    out.mkdir(parents=True, exist_ok=True)
    for obj_id, model in models.items():
        atomic_write_bytes(out / bop.model_file(obj_id), bop_ply(eval_parts(model)))
    write_models_info(models, out)


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


def write_models_info(models: Mapping[int, TargetModel], out: Path) -> None:
    """models_info.json: each model's box, diameter and symmetries (BOP's fields, where it has any), the
    same for models/ and models_eval/."""
    info = {str(obj_id): {**bop.models_info_entry(model.mesh.bounds, model.diameter), **model.symmetries}
            for obj_id, model in models.items()}  # fmt: skip
    atomic_write_text(out / bop.MODELS_INFO_FILE, json.dumps(info, indent=2) + "\n")
