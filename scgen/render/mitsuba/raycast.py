"""Exact ray casts of posed meshes through pixel centres, with Mitsuba 3: what each pixel sees, how deep.

`scgen annotate` uses it: BOP datasets arrive as meshes and poses, not as renderer Buffers; so do the
labelled objects beside the target in a render (scgen.render.objects). Rays start at the camera centre
and pass through pixel centres exactly as CameraSpec defines them; `cast_rays` is the Mitsuba backend's
geometric passes' ray cast too.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import drjit as dr
import mitsuba as mi
import numpy as np

from scgen.render.mitsuba.llvm import mitsuba_setup
from scgen.render.mitsuba.memory import aligned
from scgen.render.mitsuba.slots import MeshSlot, registry_id
from scgen.scenes.spec import CameraSpec

Box = tuple[int, int, int, int]  # x, y, w, h in pixels; may reach past the image (an enlarged canvas)


def select_variant() -> str:
    """Set the variant llvm chose for this process (llvm_ad_rgb when its libLLVM renders, else
    scalar_rgb), unless one is set already; returns the variant in use."""
    if mi.variant() is None:
        mi.set_variant(mitsuba_setup().variant)
    return mi.variant()


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


def cast_rays(
    scene: mi.Scene, shapes: list, dirs: np.ndarray, intersect: Callable | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Ray length, index of the hit shape in `shapes` (-1 = miss), geometric normal and index of the hit
    triangle in its shape, rays from the origin. `shapes`: meshes, or slots (whose meshes are known by
    their registry ids); `intersect`: intersect_from_origin or a frozen one."""
    if not dr.is_jit_v(mi.Float):
        return _cast_rays_one_by_one(scene, [s.mesh if isinstance(s, MeshSlot) else s for s in shapes], dirs)
    d = mi.Vector3f(*(mi.Float(aligned(dirs[:, k].astype(np.float32))) for k in range(3)))
    t, hit_ids, nx, ny, nz, prim, valid = (
        np.asarray(x) for x in (intersect or intersect_from_origin)(scene, d)
    )
    t = np.where(valid, t.astype(np.float64), np.inf)
    idx = np.full(len(dirs), -1, np.int64)
    if shapes:  # scene.shapes() is not in insertion order: map each hit's shape registry id to its index
        ids = np.array([s.registry_id if isinstance(s, MeshSlot) else registry_id(s) for s in shapes])
        hit_ids = hit_ids.astype(np.int64)
        lut = np.full(max(int(ids.max()), int(hit_ids.max())) + 1, -1, np.int64)
        lut[ids] = np.arange(len(shapes))
        idx = np.where(valid, lut[hit_ids], -1)
    n = np.stack([nx, ny, nz], 1).astype(np.float64)
    return t, idx, np.where(valid[:, None], n, 0.0), np.where(valid, prim, 0).astype(np.int64)


def intersect_from_origin(scene: mi.Scene, d: mi.Vector3f, **key: Any) -> tuple:
    """The first hits of rays from the origin along `d`: length, hit shape's registry id, geometric normal
    (x, y, z), triangle and whether there is one. `key`: what a frozen version is keyed by, unused here."""
    si = scene.ray_intersect(mi.Ray3f(mi.Point3f(0.0, 0.0, 0.0), d))
    shape_id = dr.reinterpret_array(mi.UInt32, si.shape)
    return si.t, shape_id, si.n.x, si.n.y, si.n.z, si.prim_index, si.is_valid()


def _cast_rays_one_by_one(
    scene: mi.Scene, shapes: list, dirs: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """cast_rays for scalar_rgb (the fallback without a usable libLLVM), whose rays go one at a time."""
    index = {id(s): k for k, s in enumerate(shapes)}
    t, idx, n = np.full(len(dirs), np.inf), np.full(len(dirs), -1, np.int64), np.zeros((len(dirs), 3))
    prim = np.zeros(len(dirs), np.int64)
    o = mi.Point3f(0.0, 0.0, 0.0)
    for i, d in enumerate(dirs.tolist()):
        si = scene.ray_intersect(mi.Ray3f(o, mi.Vector3f(d)))
        if si.is_valid():
            t[i], idx[i], n[i], prim[i] = si.t, index.get(id(si.shape), -1), si.n, si.prim_index
    return t, idx, n, prim
