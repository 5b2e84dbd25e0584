"""Mitsuba meshes kept for a worker's whole run and refilled every sample, at a fixed size.

Why: the Mitsuba backend replays its render from a frozen recording (drjit.freeze), which holds only while
every shape keeps its BSDF and every buffer its size; anything else records again, which costs what
tracing the path tracer costs (about 20 ms). So a slot is one mesh with one BSDF for good, its triangles
this sample's (unwelded: three corners each, in face order, as box_uv lays out their UVs), and the rest
of its capacity NaN: Embree leaves triangles with non-finite corners out of its BVH, so the padding is
never hit and costs little (a BVH rebuild took 0.7 ms longer with twelve empty 4716-triangle slots).
A refill writes the mesh's buffers in place (memory) and tells the mesh nothing: its bounding box
(thirteen kernel launches to compute, and read by nothing here) goes stale, and the scenes holding it are
told to rebuild their BVH by the backend (MitsubaBackend._rebuild).
"""

from __future__ import annotations

from typing import Any

import drjit as dr
import mitsuba as mi
import numpy as np

from scgen.render.mitsuba.memory import aligned, aligned_empty, overwrite


def build_mesh(name: str, corners: np.ndarray, uv: np.ndarray, bsdf: mi.BSDF) -> mi.Mesh:
    """A Mitsuba mesh of unwelded triangles: `corners` (3F x 3) and `uv` (3F x 2) hold three per face."""
    props = mi.Properties()
    props["bsdf"] = bsdf
    n = len(corners)
    m = mi.Mesh(name, n, n // 3, props=props, has_vertex_normals=False, has_vertex_texcoords=True)
    params = mi.traverse(m)
    params["vertex_positions"] = _flat(corners.astype(np.float32))
    params["faces"] = _flat(np.arange(n, dtype=np.uint32))
    params["vertex_texcoords"] = _flat(uv.astype(np.float32))
    params.update()
    return m


class MeshSlot:
    """One mesh with one BSDF, holding up to `capacity` triangles; `fill` sets this sample's.

    The buffers are written in place, in the memory they have had since the capacity last grew: a frozen
    recording keeps the address of every mesh buffer its kernels read (a replay reads that memory, whatever
    variable the mesh holds now), so a new buffer of the same size would be replayed stale.
    """

    def __init__(self, name: str, bsdf: mi.BSDF, capacity: int) -> None:
        self.triangles = 0  # how many of the capacity hold this sample's triangles
        empty = np.zeros((0, 3))
        self.mesh = build_mesh(
            name, _padded(empty, capacity), _padded(empty[:, :2], capacity, fill=0.0), bsdf
        )
        self._params = mi.traverse(self.mesh)
        self._params.keep(["vertex_positions", "vertex_texcoords", "faces"])
        self.capacity = capacity
        self._registry_id: int | None = None

    @property
    def registry_id(self) -> int:
        """The id by which Dr.Jit's ray casts name this mesh when they hit it (si.shape holds such ids);
        asked once, as evaluating it launches a kernel."""
        if self._registry_id is None:
            self._registry_id = registry_id(self.mesh)
        return self._registry_id

    def fill(self, corners: np.ndarray, uv: np.ndarray) -> None:
        """Hold these triangles (3F x 3 corners, 3F x 2 UVs); the capacity doubles until they fit, in new
        buffers (the capacity is part of what a frozen render is keyed by). The caller has waited for the
        kernels reading the buffers (drjit.sync_thread), and rebuilds the BVH of the scenes holding them."""
        n = len(corners) // 3
        if n == 0 and self.triangles == 0:
            return  # empty before and after: nothing to write
        capacity = self.capacity
        while n > capacity:
            capacity *= 2
        positions, texcoords = _padded(corners, capacity), _padded(uv, capacity, fill=0.0)
        if capacity != self.capacity or not dr.is_jit_v(mi.Float):  # scalar_rgb renders nothing frozen
            self._params["faces"] = _flat(np.arange(3 * capacity, dtype=np.uint32))
            self._params["vertex_positions"] = _flat(positions)
            self._params["vertex_texcoords"] = _flat(texcoords)
            self._params.update()
            self.capacity = capacity
        else:
            overwrite([self._params["vertex_positions"], self._params["vertex_texcoords"]],
                      [positions.ravel(), texcoords.ravel()])  # fmt: skip
        self.triangles = n


def registry_id(shape: mi.Shape) -> int:
    """The id by which Dr.Jit's ray casts name a hit shape (si.shape holds these ids)."""
    return int(np.asarray(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shape)))[0])


def _flat(values: np.ndarray) -> Any:
    """`values` (float32 or uint32) as the flat Dr.Jit array of a mesh buffer, from aligned memory."""
    tensor = mi.TensorXu if values.dtype == np.uint32 else mi.TensorXf
    return dr.ravel(tensor(aligned(values)))


def _padded(values: np.ndarray, capacity: int, fill: float = np.nan) -> np.ndarray:
    """`values` (rows of one corner each) as float32, followed by `fill` up to 3 * capacity rows."""
    out = aligned_empty((3 * capacity, values.shape[1]), np.float32)
    out[: len(values)] = values
    out[len(values) :] = fill
    return out
