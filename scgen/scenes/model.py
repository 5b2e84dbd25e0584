"""The target model: any mesh, loaded and normalised to the fixed object frame (its BOP files: model_files).

The object frame is centred on the bounding-box centre and scaled so the model's diameter (the
largest distance between two of its points) equals a fixed value; every pose refers to it.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from scgen.errors import ScgenError
from scgen.io import bop
from scgen.scenes.bundled_models import BUNDLED_MODELS, DEFAULT_MODEL
from scgen.scenes.materials import MATERIALS

SYMMETRY_KEYS = ("symmetries_discrete", "symmetries_continuous")  # BOP's models_info fields

_MATERIAL_KEYWORDS = (
    ("gold", "mli_gold"),
    ("mli", "mli_silver"),
    ("silver", "mli_silver"),
    ("foil", "mli_silver"),
    ("solar", "solar_cell"),
    ("cell", "solar_cell"),
    ("panel", "solar_cell"),
    ("paint", "white_paint"),
    ("white", "white_paint"),
    ("black", "dark_metal"),
    ("dark", "dark_metal"),
    ("metal", "brushed_metal"),
    ("alu", "brushed_metal"),
)
DEFAULT_DIAMETER_M = 0.2
PARTS_FILE = "parts.glb"


@dataclass
class TargetModel:
    """Normalised target: parts (material, mesh) in metres in the object frame, plus the merged mesh."""

    name: str
    parts: list[tuple[str, trimesh.Trimesh]]
    mesh: trimesh.Trimesh
    diameter: float
    symmetries: dict[str, Any] = field(default_factory=dict)  # BOP's SYMMETRY_KEYS, as in models_info

    @property
    def fingerprint(self) -> str:
        """A hash of the normalised geometry, used to refuse resuming into another model's dataset."""
        h = hashlib.sha256()
        for material, m in self.parts:
            h.update(material.encode())
            h.update(np.round(np.asarray(m.vertices, dtype=np.float64), 7).tobytes())
            h.update(np.asarray(m.faces, dtype=np.int64).tobytes())
        if self.symmetries:  # a model without (every one before the fleet) keeps its fingerprint
            h.update(json.dumps(self.symmetries, sort_keys=True).encode())
        return h.hexdigest()[:16]


def mesh_diameter(vertices: np.ndarray) -> float:
    """Largest distance between two vertices (exact, via the convex hull)."""
    pts = np.unique(np.asarray(vertices, dtype=np.float64), axis=0)
    if len(pts) > 4:  # the farthest pair lies on the hull (trimesh joggles flat sets with QJ)
        pts = np.asarray(trimesh.convex.convex_hull(pts).vertices)
    return float(max(np.linalg.norm(pts - p, axis=1).max() for p in pts))


def normalise_parts(
    parts: list[tuple[str, trimesh.Trimesh]],
    diameter_m: float | None = DEFAULT_DIAMETER_M,
    name: str = "model",
) -> TargetModel:
    """Centre the parts on their joint bbox centre and scale them to `diameter_m` (None keeps the scale)."""
    parts = [(mat, m.copy()) for mat, m in parts if len(m.faces) > 0]
    if not parts:
        raise ScgenError(f"mesh '{name}' has no triangles")
    merged = trimesh.util.concatenate([m for _, m in parts])
    lo, hi = merged.bounds
    centre = 0.5 * (lo + hi)
    diameter = mesh_diameter(merged.vertices)
    if not np.isfinite(diameter) or diameter <= 0:
        raise ScgenError(f"mesh '{name}' is degenerate (zero extent)")
    scale = 1.0 if diameter_m is None else diameter_m / diameter
    for _, m in parts:
        m.apply_translation(-centre)
        m.apply_scale(scale)
    merged = trimesh.util.concatenate([m for _, m in parts])
    return TargetModel(name=name, parts=parts, mesh=merged, diameter=diameter * scale)


def material_for(name: str | None) -> str:
    """Map a CAD material (or part) name onto one of the renderer's spacecraft materials."""
    low = (name or "").lower()
    if low in MATERIALS:
        return low
    for key, material in _MATERIAL_KEYWORDS:
        if key in low:
            return material
    return "white_paint"


def load_mesh_parts(path: Path) -> list[tuple[str, trimesh.Trimesh]]:
    """Read OBJ/PLY/GLB/GLTF/STL into (material, mesh) parts; the CAD's material names are kept."""
    if not path.exists():
        raise ScgenError(f"mesh not found: {path} (nor is it a bundled model: {', '.join(BUNDLED_MODELS)})")
    if path.suffix.lower() not in (".obj", ".ply", ".glb", ".gltf", ".stl", ".off"):
        raise ScgenError(
            f"unsupported mesh format '{path.suffix}' for {path} (use OBJ, PLY, GLB, GLTF or STL)"
        )
    try:
        loaded = trimesh.load(str(path), force="scene", process=False)
    except Exception as exc:  # trimesh raises many types for corrupt files
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ScgenError(f"cannot read mesh {path}: {reason}") from None
    parts = []
    for geom_name, geom in loaded.geometry.items():
        if not isinstance(geom, trimesh.Trimesh) or len(geom.faces) == 0:
            continue
        mesh = geom.copy()
        transforms = loaded.graph.geometry_nodes.get(geom_name, [])
        if transforms:
            mesh.apply_transform(loaded.graph.get(transforms[0])[0])
        mat = getattr(getattr(geom.visual, "material", None), "name", None)
        parts.append((material_for(mat or geom_name), mesh))
    if not parts:
        raise ScgenError(f"mesh {path} has no triangles")
    return parts


def bundled_model_dir(name: str) -> Path:
    """The folder of bundled model `name` (BUNDLED_MODELS): package data, so an installed wheel finds it
    anywhere."""
    return Path(str(files("scgen") / "assets" / name))


def load_target(path: str | Path | None = None, keep_scale: bool = False) -> TargetModel:
    """A bundled model by name (BUNDLED_MODELS; None: the default spacecraft), stored normalised with its
    symmetries in its models_info.json, or any user mesh, normalised to the object frame."""
    name = DEFAULT_MODEL if path is None else str(path)
    if name in BUNDLED_MODELS:
        folder = bundled_model_dir(name)
        if not (folder / PARTS_FILE).exists():
            raise ScgenError(
                f"bundled model missing at {folder}: reinstall scgen, or in a checkout run `make assets`"
            )
        model = normalise_parts(load_mesh_parts(folder / PARTS_FILE), diameter_m=None, name=name)
        (info,) = bop.read_json(folder / bop.MODELS_INFO_FILE).values()
        model.symmetries = {k: info[k] for k in SYMMETRY_KEYS if k in info}
        return model
    path = Path(path)  # type: ignore[arg-type]
    return normalise_parts(load_mesh_parts(path), None if keep_scale else DEFAULT_DIAMETER_M, name=path.stem)
