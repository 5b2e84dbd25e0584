"""What the Earth's surface reflects: a procedural planet, or NASA Blue Marble under procedural clouds.

Both give, at Earth-fixed unit vectors q, the surface albedo (linear RGB, clouds included), the water
share (where the sun glints) and the cloud cover. backgrounds.py shades them under the sun and the
atmosphere; `disc_albedo` averages the Blue Marble surface over the lit visible disc for the Earth's
reflected light on the target (scgen.render.lighting).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from scgen.render.conventions import LUMA
from scgen.render.sky import bluemarble
from scgen.render.sky.textures import equirect, equirect_at, lat_lon, periodic_noise
from scgen.scenes.sky import body_centre, earth_frame

EARTH_OCEAN = np.array([0.010, 0.030, 0.085])
EARTH_LAND = (np.array([0.06, 0.09, 0.035]), np.array([0.23, 0.17, 0.10]))  # vegetation, desert
EARTH_ICE, EARTH_CLOUD = np.array([0.75, 0.78, 0.82]), np.array([0.72, 0.73, 0.75])
EARTH_MAP = (512, 1024)  # equirectangular size of the procedural maps (land, clouds)
CLOUD_STREAM = 1  # Blue Marble clouds: np.random.default_rng([background seed, CLOUD_STREAM])
# Blue Marble clouds: cover = clip(CLOUD_GAIN * (noise - CLOUD_THRESHOLD)), half the globe under some cloud
# and a mean cover of about 0.33, so the disc reflects about the Earth's Bond albedo, 0.3
CLOUD_THRESHOLD, CLOUD_GAIN = 0.0, 0.8
LAND_DETAIL, CLOUD_DETAIL = 0.35, 0.4  # contrast of the sub-map detail (log albedo, log cloud cover)
POLE_TO_EQUATOR = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # a turn about y
DISC_POINTS = 4096  # surface points averaged by disc_albedo


def procedural_surface(rng: np.random.Generator, q: np.ndarray) -> tuple[np.ndarray, ...]:
    """(albedo N x 3, water N x 1, cloud N x 1) of 1/f-noise continents, ice caps and clouds drawn from
    `rng`: about a third of the surface is land, about 30 % is under cloud."""
    tex_h, tex_w = EARTH_MAP
    height = equirect(periodic_noise(rng, tex_h, tex_w, beta=3.2), q)
    dry = equirect(periodic_noise(rng, tex_h, tex_w, beta=3.0), q)
    cloud_map = periodic_noise(rng, tex_h, tex_w, beta=2.4, aspect=0.7)
    land = np.clip((height - 0.45) * 6, 0, 1)[:, None]
    dry = np.clip(0.5 + 0.6 * dry, 0, 1)[:, None]
    ice = np.clip((np.abs(q[:, 2]) - 0.95) * 40, 0, 1)[:, None]
    cloud = np.clip((equirect(cloud_map, q) - 0.5) * 0.9, 0, 1)[:, None]
    depth = np.clip(0.6 - 0.25 * height, 0.3, 1.0)[:, None]  # shallow seas are lighter
    ground = (1 - dry) * EARTH_LAND[0] + dry * EARTH_LAND[1]
    surface = (1 - land) * EARTH_OCEAN / depth + land * ground
    surface = (1 - ice) * surface + ice * EARTH_ICE
    surface = (1 - cloud) * surface + cloud * EARTH_CLOUD
    return surface, 1 - land, cloud


@functools.lru_cache(maxsize=2)  # the background and the Earth's light of one sample share it
def cloud_map(seed: int) -> np.ndarray:
    """The procedural cloud field over a Blue Marble Earth, from the sample's background seed."""
    rng = np.random.default_rng([seed, CLOUD_STREAM])
    return periodic_noise(rng, *EARTH_MAP, beta=2.4, aspect=0.7)


def cloud_cover(seed: int, q: np.ndarray, at: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """The cloud field (zero mean, unit deviation) at Earth-fixed unit vectors q (N x 3). Near the poles,
    where an equirectangular map pinches into radial streaks, it is read in a frame turned by 90 degrees
    (the poles on its equator), blended in between at the same deviation. `at`: q's latitudes and
    longitudes where the caller has them (textures.lat_lon)."""
    field = cloud_map(seed)
    lat, lon = lat_lon(q) if at is None else at
    w = np.clip((0.85 - np.abs(q[:, 2])) / 0.25, 0.0, 1.0)  # 1 below 37 deg of latitude, 0 above 58
    # each frame read only where it weighs (a weight of 0 adds nothing)
    plain, polar = np.zeros(len(q), np.float32), np.zeros(len(q), np.float32)
    some = w > 0
    plain[some] = equirect_at(field, lat[some], lon[some])
    some = w < 1
    polar[some] = equirect(field, q[some] @ POLE_TO_EQUATOR.T)
    return (w * plain + (1 - w) * polar) / np.sqrt(w**2 + (1 - w) ** 2)


def bluemarble_surface(q: np.ndarray, lod: np.ndarray, seed: int) -> tuple[np.ndarray, ...]:
    """(albedo N x 3, water N x 1, cloud N x 1): Blue Marble at level of detail `lod` (see
    bluemarble.lookup), flat oceans, and procedural clouds from `seed`."""
    at = lat_lon(q)
    texel = bluemarble.lookup(q, lod, at)
    water = texel[:, 3:]
    land_detail, cloud_detail = bluemarble.details(q, lod, (0.0, 97.0), at)
    ground = texel[:, :3] * np.exp(LAND_DETAIL * land_detail)[:, None]
    surface = (1 - water) * ground + water * EARTH_OCEAN
    texture = np.exp(CLOUD_DETAIL * cloud_detail)  # within clouds: no new wisps
    cloud = np.clip((cloud_cover(seed, q, at) - CLOUD_THRESHOLD) * CLOUD_GAIN * texture, 0, 1)[:, None]
    return (1 - cloud) * surface + cloud * EARTH_CLOUD, water, cloud


def disc_albedo(params: dict[str, Any], sun: np.ndarray, seed: int) -> float:
    """Mean albedo (luminance) of the Blue Marble Earth over its lit visible disc, each surface point
    weighted by its sunlit cosine and its projected area towards the camera (mu_s * mu_v); 0 when no
    lit point is visible."""
    to_camera = -body_centre(params)  # Earth centre -> camera
    k = np.arange(DISC_POINTS) + 0.5
    z = 1 - 2 * k / DISC_POINTS  # Fibonacci sphere: equal-area points
    phi = np.pi * (1 + 5**0.5) * k
    n = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], axis=1)
    view = to_camera - n
    mu_v = np.sum(n * view, axis=1) / np.linalg.norm(view, axis=1)
    weight = np.clip(n @ sun, 0, None) * np.clip(mu_v, 0, None)
    if weight.sum() <= 0:
        return 0.0
    keep = weight > 0
    q = n[keep] @ earth_frame(params).T
    albedo, _, _ = bluemarble_surface(q, np.full(len(q), bluemarble.LEVELS - 1.0), seed)
    return float(weight[keep] @ (albedo @ LUMA) / weight.sum())
