"""Exact ray casts of posed meshes through pixel centres, with Mitsuba 3: what each pixel sees, how deep.

`scgen annotate` uses it: BOP datasets arrive as meshes and poses, not as renderer Buffers. Rays start
at the camera centre and pass through pixel centres exactly as CameraSpec defines them, through the same
Mitsuba ray cast as the Mitsuba backend's geometric passes.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from scgen.render.mitsuba.backend import cast_rays, select_variant
from scgen.scenes.spec import CameraSpec

Box = tuple[int, int, int, int]  # x, y, w, h in pixels; may reach past the image (an enlarged canvas)


def start(threads: int | None = None) -> None:
    """Pick Mitsuba's variant (once per process) and, if given, its thread count."""
    select_variant()
    if threads is not None:
        dr.set_thread_count(threads)


def place_mesh(name: str, vertices: np.ndarray, faces: np.ndarray, R: np.ndarray, t: np.ndarray) -> mi.Mesh:
    """A Mitsuba mesh of model-frame vertices (metres) moved into the camera frame by X = R·C + t."""
    mesh = mi.Mesh(name, len(vertices), len(faces), has_vertex_normals=False, has_vertex_texcoords=False)
    params = mi.traverse(mesh)
    params["vertex_positions"] = dr.ravel(mi.TensorXf((vertices @ R.T + t).astype(np.float32)))
    params["faces"] = dr.ravel(mi.TensorXu(np.asarray(faces, dtype=np.uint32)))
    params.update()
    return mesh


def cast(shapes: list[mi.Mesh], camera: CameraSpec, canvas: Box) -> tuple[np.ndarray, np.ndarray]:
    """(index in `shapes` of the first hit, -1 for none; its depth z in metres, 0 for none), h x w each.

    One ray per pixel centre (u, v) of `canvas`, which may extend past the image (for the full
    projection of an object the image cuts); pixel (u, v) of the canvas is row v - y, column u - x.
    """
    x, y, w, h = canvas
    v, u = np.mgrid[y : y + h, x : x + w].astype(np.float64)
    rays = camera.rays(u, v).reshape(-1, 3)
    dirs = rays / np.linalg.norm(rays, axis=1, keepdims=True)
    scene = mi.load_dict({"type": "scene", **{f"s{k:04d}": s for k, s in enumerate(shapes)}})
    dist, index, *_ = cast_rays(scene, shapes, dirs)
    depth = np.where(index >= 0, dist * dirs[:, 2], 0.0)
    return index.reshape(h, w), depth.reshape(h, w)
