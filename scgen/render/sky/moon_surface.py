"""What the Moon's surface reflects: a procedural Moon of maria, highlands and craters.

One Moon for every sample (a fixed seed; each sample turns it at random): at selenographic unit vectors
q it gives the normal albedo and the surface slope that craters and relief add. The albedos are the
Moon's: highlands about 0.14, maria about 0.07 over about a sixth of the surface, so the disc averages
about 0.12, the Moon's geometric albedo. backgrounds.py shades it under the sun; airless, it has no
haze, no glow above its limb, and its night side is black.
"""

from __future__ import annotations

import functools

import numpy as np

from scgen.render.sky.textures import equirect, periodic_noise

MOON_MAP = (1024, 2048)  # equirectangular size of the height and albedo maps (0.18 deg a texel)
MOON_SEED = 0x4D4F4F4E  # the one Moon
HIGHLAND_ALBEDO, MARE_ALBEDO = 0.14, 0.07
MARE_SHARE = 0.16  # of the surface
CRATERS = 6000  # craters stamped into the height map, radii 0.4-12 deg with N(>r) ~ 1/r^2
CRATER_RADIUS_DEG = (0.4, 12.0)
RELIEF = 0.015  # rolling relief between craters: height deviation in Moon radii
MAX_SLOPE = 0.8  # tan of the steepest slope shaded (39 deg; the map's poles would give more)


@functools.lru_cache(maxsize=1)
def moon_maps() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(albedo, d height / d latitude, d height / (cos(latitude) d longitude)): equirectangular maps
    (rows: latitude +90..-90), heights in Moon radii, so the slopes are in radians of tilt."""
    rng = np.random.default_rng(MOON_SEED)
    h, w = MOON_MAP
    iso = w / h  # periodic_noise's aspect that makes features round on the sphere's equator
    lat = np.deg2rad(90.0 - 180.0 * (np.arange(h) + 0.5) / h)[:, None]
    fade = np.cos(lat)  # the map's noise fades towards its poles, where its texels crowd into streaks
    basins = periodic_noise(rng, h, w, beta=4.0, aspect=iso)
    mare = np.clip((basins - np.quantile(basins, 1 - MARE_SHARE)) * 4.0 + 0.5, 0, 1)
    grain = 1.0 + 0.12 * fade * periodic_noise(rng, h, w, beta=2.0, aspect=iso)
    albedo = ((1 - mare) * HIGHLAND_ALBEDO + mare * MARE_ALBEDO) * grain
    relief = periodic_noise(rng, h, w, beta=3.0, aspect=iso)
    height = RELIEF * fade * relief * (1 - 0.7 * mare)  # maria are smooth plains
    _stamp_craters(rng, height, albedo)  # placed on the sphere: round at every latitude
    d_lat = -np.gradient(height, np.pi / h, axis=0)  # rows run north to south
    d_lon = np.gradient(np.pad(height, ((0, 0), (1, 1)), mode="wrap"), 2 * np.pi / w, axis=1)[:, 1:-1]
    d_east = d_lon / np.maximum(np.cos(lat), 0.02)
    d_lat, d_east = (np.clip(d, -MAX_SLOPE, MAX_SLOPE).astype(np.float32) for d in (d_lat, d_east))
    return albedo.astype(np.float32), d_lat, d_east


def _stamp_craters(rng: np.random.Generator, height: np.ndarray, albedo: np.ndarray) -> None:
    """Bowl-shaped craters with raised rims (depth a fifth of the radius, a rim a twentieth), each with
    a bright fresh floor or ray-less halo for the youngest, stamped in place on the maps."""
    h, w = height.shape
    lo, hi = np.deg2rad(CRATER_RADIUS_DEG)
    u = rng.uniform(size=CRATERS)
    radii = lo / np.sqrt(1 - u * (1 - (lo / hi) ** 2))  # N(>r) ~ r^-2 between lo and hi
    centres = rng.normal(size=(CRATERS, 3))
    centres /= np.linalg.norm(centres, axis=1, keepdims=True)
    fresh = rng.uniform(size=CRATERS) < 0.1
    lat_c, lon_c = np.arcsin(centres[:, 2]), np.arctan2(centres[:, 1], centres[:, 0])
    row_lat = np.deg2rad(90.0 - 180.0 * (np.arange(h) + 0.5) / h)
    col_lon = np.deg2rad(-180.0 + 360.0 * (np.arange(w) + 0.5) / w)
    for r, c, la, lo_c, young in zip(radii, centres, lat_c, lon_c, fresh, strict=True):
        reach = 1.6 * r
        rows = np.nonzero(np.abs(row_lat - la) <= reach)[0]
        if np.cos(la) - reach <= 0.05:  # touches a pole: every longitude
            cols = np.arange(w)
        else:
            half = reach / max(np.cos(abs(la) + reach), 0.05)
            cols = np.nonzero(np.abs((col_lon - lo_c + np.pi) % (2 * np.pi) - np.pi) <= half)[0]
        lat, lon = row_lat[rows][:, None], col_lon[cols][None, :]
        cos_angle = np.cos(lat) * (np.cos(lon) * c[0] + np.sin(lon) * c[1]) + np.sin(lat) * c[2]
        x = np.arccos(np.clip(cos_angle, -1, 1)) / r  # distance from the centre in crater radii
        bowl = np.where(x < 1, x**2 - 1, 0.0) * 0.2 * r
        rim = 0.05 * r * np.exp(-(((x - 1) / 0.25) ** 2))
        height[np.ix_(rows, cols)] += bowl + rim
        if young:
            albedo[np.ix_(rows, cols)] *= 1.0 + 0.5 * np.exp(-((x / 1.3) ** 4))


def moon_surface(q: np.ndarray, n: np.ndarray, east: np.ndarray, north: np.ndarray) -> tuple[np.ndarray, ...]:
    """(albedo N, shading normals N x 3) at selenographic unit vectors q, whose camera-frame normals are
    n with local east and north unit vectors (N x 3 each): the normal tilted by the surface's slopes."""
    albedo, d_lat, d_lon = moon_maps()
    s_north, s_east = equirect(d_lat, q), equirect(d_lon, q)
    tilted = n - s_east[:, None] * east - s_north[:, None] * north
    return equirect(albedo, q), tilted / np.linalg.norm(tilted, axis=1, keepdims=True)
