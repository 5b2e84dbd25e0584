"""Spacecraft material classes as Mitsuba BSDFs, with procedural, deterministic detail textures.

Base parameters come from the registry scgen.scenes.materials, as for the Blender backend; the details are
this backend's: crinkled MLI foil (a tileable ridged normal map),
solar cells (a grid of cells and busbars), anisotropic brushed metal, paint, dark metal.
Textures are laid on by box projection in the object's own frame, sized by the object's size.
Only shading changes: the geometry (and so every label) is the same triangles as before.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import drjit as dr
import mitsuba as mi
import numpy as np

from scgen.io.machine_cache import cached_arrays
from scgen.render.mitsuba.memory import aligned, channels, check_held, overwrite, own_scalars
from scgen.scenes.finish import finished
from scgen.scenes.materials import BUSBAR_COLOUR, CELLS_PER_SIZE, MATERIALS, Material

CRINKLE_TILES_PER_SIZE = 2.0  # a tile spans half the object: no visible repetition on a face
TEXTURE_SEED = 2024  # the detail textures are fixed assets, identical for every sample
CRINKLE_SLOPE = 0.02  # the nominal crinkle's height-gradient scale


@functools.cache
def _crinkle_gradient(size: int = 512, waves: int = 64) -> tuple[np.ndarray, ...]:
    """Height gradient (d/dx, d/dy per tile) of crumpled foil: a ridged sum of random integer-frequency
    plane waves (2 to 14 per tile, so about 4 to 28 creases per object size), creased where a wave
    crosses zero; tileable. Made once on a machine (~0.2 s) and kept in scgen's cache."""
    make = functools.partial(_make_crinkle_gradient, size, waves)
    return cached_arrays(f"crinkle_gradient_{size}_{waves}", (Path(__file__),), (), make)


def _make_crinkle_gradient(size: int, waves: int) -> tuple[np.ndarray, np.ndarray]:
    """_crinkle_gradient, made from TEXTURE_SEED."""
    rng = np.random.default_rng(TEXTURE_SEED)
    y, x = np.mgrid[0:size, 0:size] / size
    h = np.zeros((size, size))
    for _ in range(waves):
        k = rng.uniform(2, 14)
        a = rng.uniform(0, np.pi)
        kx, ky = np.round(k * np.cos(a)), np.round(k * np.sin(a))  # integer: the tile wraps seamlessly
        amp = 1.0 / max(1.0, float(np.hypot(kx, ky)))
        h -= amp * np.abs(np.sin(np.pi * (kx * x + ky * y) + rng.uniform(0, np.pi)))
    gy, gx = np.gradient(h, 1.0 / size)
    return gx, gy


def crinkle_normal_map(slope: float = CRINKLE_SLOPE) -> np.ndarray:
    """A tileable tangent-space normal map (512 x 512 x 3 in [0, 1]) of crumpled foil; `slope` scales
    the height gradient (the crinkle's strength)."""
    gx, gy = _crinkle_gradient()
    nx, ny, length = _tilted_normal(gx, gy, slope, np.sqrt)
    return np.stack([_encoded(c, length).astype(np.float32) for c in (nx, ny, 1.0)], axis=-1)


def crinkle_normal_tensor(slope: float) -> mi.TensorXf:
    """crinkle_normal_map as a Dr.Jit tensor, computed by one kernel in a JIT variant (a sample sets two;
    numpy took 3 ms each), bit for bit the same values: the same float64 operations in the same order, no
    contraction into FMAs, then rounded to float32. The slope enters opaque, so one kernel serves all."""
    if not dr.is_jit_v(mi.Float):
        return mi.TensorXf(crinkle_normal_map(slope))
    gx, gy = _crinkle_gradient_jit()
    entry = dr.arange(mi.UInt32, 3 * dr.width(gx))  # the map's values in memory order: pixel, channel
    pixel, channel = entry // 3, entry % 3
    nx, ny, length = _tilted_normal(dr.gather(mi.Float64, gx, pixel), dr.gather(mi.Float64, gy, pixel),
                                    dr.opaque(mi.Float64, slope), dr.sqrt)  # fmt: skip
    component = dr.select(channel == 0, nx, dr.select(channel == 1, ny, 1.0))  # one division per value
    return mi.TensorXf(mi.Float(_encoded(component, length)), shape=_crinkle_gradient()[0].shape + (3,))


@functools.cache
def _crinkle_gradient_jit() -> tuple[Any, Any]:
    """_crinkle_gradient as flat Dr.Jit float64 arrays (per variant: the cache lives in one process)."""
    return tuple(mi.Float64(g.ravel()) for g in _crinkle_gradient())


def _tilted_normal(gx: Any, gy: Any, slope: Any, sqrt: Any) -> tuple[Any, Any, Any]:
    """The normal along (-slope gx, -slope gy, 1): its x and y, and its length; one formula for numpy's
    arrays and Dr.Jit's."""
    nx, ny = gx * -slope, gy * -slope
    return nx, ny, sqrt(nx * nx + ny * ny + 1.0)


def _encoded(component: Any, length: Any) -> Any:
    """One channel of the map, 0.5 n + 0.5 of the unit normal: a component over the normal's length."""
    return component / length * 0.5 + 0.5


def cell_texture(
    base: tuple[float, float, float] = MATERIALS["solar_cell"].base, size: int = 64
) -> np.ndarray:
    """One solar cell (a tile): the cell colour `base` with a light frame and two busbars, linear RGB."""
    tex = np.tile(np.asarray(base, np.float32), (size, size, 1))
    line = max(1, size // 32)
    for a in (slice(0, line), slice(size - line, size)):
        tex[a, :] = BUSBAR_COLOUR
        tex[:, a] = BUSBAR_COLOUR
    for c in (size // 3, 2 * size // 3):
        tex[:, c - line // 2 : c - line // 2 + line] = BUSBAR_COLOUR
    return tex


def _bitmap(array: np.ndarray, raw: bool) -> dict[str, Any]:
    return {"type": "bitmap", "bitmap": mi.Bitmap(array), "raw": raw, "filter_type": "bilinear",
            "wrap_mode": "repeat"}  # fmt: skip


def _principled(base: Any, roughness: float, metallic: float = 0.0, **extra: float) -> dict[str, Any]:
    colour = base if isinstance(base, dict) else {"type": "rgb", "value": list(base)}
    return {"type": "principled", "base_color": colour, "roughness": roughness, "metallic": metallic, **extra}


def build_bsdfs() -> dict[str, mi.BSDF]:
    """One BSDF object per material class, built once per backend and shared by every mesh."""
    return {name: finish_bsdf(m) for name, m in MATERIALS.items()}


def finish_bsdf(m: Material) -> mi.BSDF:
    """The BSDF of a material (a class's nominal finish or a sample's draw), details included."""
    base = _bitmap(cell_texture(m.base), raw=False) if m.detail == "cells" else m.base
    bsdf = _principled(base, m.roughness, m.metallic, specular=m.specular, anisotropic=m.anisotropic)
    if m.detail == "crinkle":
        normals = _bitmap(crinkle_normal_map(CRINKLE_SLOPE * m.crinkle), raw=True)
        bsdf = {"type": "normalmap", "normalmap": normals, "bsdf": bsdf}
    return mi.load_dict(bsdf)


class TargetFinishes:
    """The target's BSDFs under per-sample finishes, kept per class drawn: each sample takes one of that
    class's BSDFs per part class drawing it, sets it to the sample's values in place (mi.traverse), and
    builds one only when all are taken (two part classes drawing one class).

    Dr.Jit traces every live BSDF into each render kernel, used by the scene or not, and a new BSDF means
    a new kernel (and, for a frozen render, recording every render again). So each class starts with
    `per_class` BSDFs (the default config needs a third one in a few samples per thousand, a fourth in a
    few per 50,000), and the set stays small: one BSDF per (part class, class drawn) would be 36.
    """

    def __init__(self, per_class: int = 1) -> None:
        # class drawn -> its BSDFs, each with what a sample sets of it (FinishParameters)
        self._pools: dict[str, list[tuple[mi.BSDF, FinishParameters]]] = {}
        for name, m in MATERIALS.items():
            self._pools[name] = [self._kept(m) for _ in range(per_class)]

    @staticmethod
    def _kept(m: Material) -> tuple[mi.BSDF, FinishParameters]:
        bsdf = finish_bsdf(m)
        return bsdf, FinishParameters(bsdf, m)

    def pooled(self) -> list[tuple[str, mi.BSDF]]:
        """Every BSDF kept, with its name (as `bsdfs` names it)."""
        return [
            (_pool_name(drawn, k), b) for drawn, pool in self._pools.items() for k, (b, _) in enumerate(pool)
        ]

    def bsdfs(self, finish: dict[str, dict]) -> dict[str, tuple[str, mi.BSDF]]:
        """The BSDF of every part class under a sample's finish (scgen.scenes.finish), each with a name
        that stays its own for good (the class drawn and the BSDF's place in that class's pool)."""
        taken: dict[str, int] = {}
        out = {}
        for part_class in sorted(finish):
            drawn, m = finish[part_class]["material"], finished(finish, part_class)
            pool = self._pools.setdefault(drawn, [])
            k = taken[drawn] = taken.get(drawn, -1) + 1
            if k == len(pool):
                pool.append(self._kept(m))
            else:
                pool[k][1].set(m)
            out[part_class] = _pool_name(drawn, k), pool[k][0]
        return out


def _pool_name(drawn: str, k: int) -> str:
    """The name of the k-th BSDF kept for the class drawn."""
    return f"{drawn}_{k}"


class FinishParameters:
    """What a sample sets of a BSDF built by finish_bsdf: its numbers (colour, roughness, metallic) are
    written in place into memory of their own (memory; through mi.traverse, one kernel launch
    each), its textures (the crinkle's normal map, the cells' colours) set through mi.traverse."""

    def __init__(self, bsdf: mi.BSDF, m: Material) -> None:
        self._params = mi.traverse(bsdf)  # traversed once: a traversal costs 0.2 ms
        self._floats: list[mi.Float] = []  # the Floats of _numbers(m)'s parameters, in their order
        if dr.is_jit_v(mi.Float):
            keys = list(_numbers(m))
            for key in keys:
                value = self._params[key]
                owned = own_scalars(f[0] for f in channels(value))
                self._params[key] = mi.Color3f(*owned) if isinstance(value, mi.Color3f) else owned[0]
            self._params.update()
            self._floats = [f for key in keys for f in channels(self._params[key])]
            live = mi.traverse(bsdf)
            check_held(self._floats, [f for key in keys for f in channels(live[key])], "BSDF")

    def set(self, m: Material) -> None:
        """Set the BSDF to `m`'s values (a material of the class it was built for): it renders what a new
        one would. The caller has waited for the kernels reading them (drjit.sync_thread)."""
        numbers = _numbers(m)
        if dr.is_jit_v(mi.Float):
            overwrite(self._floats, [v for values in numbers.values() for v in values])
        else:  # scalar_rgb: plain numbers, set the usual way
            for key, values in numbers.items():
                self._params[key] = mi.Color3f(*values) if len(values) == 3 else values[0]
        if m.detail == "cells":
            self._params["base_color.data"] = mi.TensorXf(aligned(cell_texture(m.base)))
        if m.detail == "crinkle":
            self._params["normalmap.data"] = crinkle_normal_tensor(CRINKLE_SLOPE * m.crinkle)
        self._params.update()


def _numbers(m: Material) -> dict[str, tuple[float, ...]]:
    """The parameters of a BSDF built for `m`'s class that a sample sets to numbers, with `m`'s: its colour
    (unless textured), roughness, and metallic where the class has any (setting it would mark the BSDF
    metallic for good)."""
    inner = "nested_bsdf." if m.detail == "crinkle" else ""
    numbers = {} if m.detail == "cells" else {inner + "base_color.value": tuple(m.base)}
    numbers[inner + "roughness.value"] = (m.roughness,)
    if m.metallic:
        numbers[inner + "metallic.value"] = (m.metallic,)
    return numbers


def texture_scale(material: str, size: float) -> float:
    """UV units per metre: texture tiles are fixed fractions of the object's size (target diameter,
    or a prop's longest side), so detail keeps its look on big background structures too."""
    per_size = CELLS_PER_SIZE if material == "solar_cell" else CRINKLE_TILES_PER_SIZE
    return per_size / size


def box_uv(vertices: np.ndarray, faces: np.ndarray, scale: float) -> np.ndarray:
    """Box-projected UVs of the unwelded triangles (3F x 2: three corners per face, in face order).

    Each face takes the two coordinates orthogonal to the dominant axis of its normal, in the frame
    `vertices` are given in (the object's own frame, so textures stick to the object).
    """
    tri = vertices[faces]  # F x 3 x 3
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    keep = np.array([[1, 2], [2, 0], [0, 1]])[np.argmax(np.abs(normal), axis=1)]  # F x 2
    uv = np.take_along_axis(tri, np.repeat(keep[:, None, :], 3, axis=1), axis=2) * scale
    return uv.reshape(-1, 2)
