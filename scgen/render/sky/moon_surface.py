"""What the Moon's surface reflects: a procedural Moon of maria, highlands and craters.

One Moon for every sample (a fixed seed; each sample turns it at random): at selenographic unit vectors
q it gives the normal albedo and the surface slope that craters and relief add. The albedos are the
Moon's: highlands about 0.14, maria about 0.07 over about a sixth of the surface, so the disc averages
about 0.12, the Moon's geometric albedo. backgrounds.py shades it under the sun; airless, it has no
haze, no glow above its limb, and its night side is black.

The maps hold the large craters (radii 12-360 km) at 5.5 km a texel. Below that, craters come from a
procedural field evaluated at each pixel (fine_craters): octaves of craters down to 40 m, each octave
drawn only where the pixel footprint resolves it, so that the Moon seen from 100 km up is as cratered as
its disc from afar, and no crater smaller than a pixel aliases.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from scgen.io.machine_cache import cached_arrays
from scgen.render.sky import textures
from scgen.render.sky.rows import row_dot, row_norm
from scgen.render.sky.textures import equirect, periodic_noise

MOON_MAP = (1024, 2048)  # equirectangular size of the height and albedo maps (0.18 deg a texel)
MOON_SEED = 0x4D4F4F4E  # the one Moon
HIGHLAND_ALBEDO, MARE_ALBEDO = 0.14, 0.07
MARE_SHARE = 0.16  # of the surface
CRATERS = 6000  # craters stamped into the height map, radii 0.4-12 deg with N(>r) ~ 1/r^2
CRATER_RADIUS_DEG = (0.4, 12.0)
RELIEF = 0.003  # rolling relief between craters: height deviation in Moon radii (5 km; LOLA's is ~2-3 km)
MAX_SLOPE = 0.8  # tan of the steepest slope shaded (39 deg; the map's poles would give more)
# The fine crater field: octave k has 3D cells of FINE_CELL / 2^k Moon radii; each cell holds CANDIDATES
# crater centres, jittered in it, kept where they lie within SHELL cells of the surface, so that with
# reach (REACH radii) <= (0.5 - SHELL) cells the 2 x 2 x 2 cells nearest a point hold every crater that
# touches it. Radii 0.08-0.22 cells: the first octave continues the map's smallest craters (12 km).
FINE_CELL, FINE_OCTAVES, CANDIDATES, SHELL = 0.05, 9, 3, 0.15
FINE_RADIUS = (0.08, 0.22)  # of the cell
REACH = 1.6  # crater radii: the raised rim's extent
RESOLVED_PX = (4.0, 12.0)  # an octave fades in between these cell sizes in pixels (radii of ~0.6-1.8 px)


@functools.lru_cache(maxsize=1)
def moon_maps() -> tuple[np.ndarray, ...]:
    """(albedo, d height / d latitude, d height / (cos(latitude) d longitude)): equirectangular maps
    (rows: latitude +90..-90), heights in Moon radii, so the slopes are in radians of tilt. Made once on
    a machine (~1 s) and kept in scgen's cache (scgen.io.machine_cache): the same bits in every process."""
    return cached_arrays("moon_maps", (Path(__file__), Path(textures.__file__)), (), _make_moon_maps)


@functools.lru_cache(maxsize=1)
def _stacked_maps() -> np.ndarray:
    """moon_maps as one H x W x 3 array (albedo, d height / d latitude, d height / d east), so that one
    look-up reads all three."""
    return np.dstack(moon_maps())


def _make_moon_maps() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """moon_maps, made from the one Moon's seed."""
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
        reach = REACH * r
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


def crater_profile_slope(x: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """d height / d distance of a crater at x crater radii from its centre: a bowl `depth` radii deep
    (depth (x^2 - 1) inside) with a raised rim a fifth as high (Gaussian, width a quarter radius)."""
    rim = 0.2 * depth * np.exp(-(((x - 1) / 0.25) ** 2))
    return np.where(x < 1, 2 * depth * x, 0.0) - 2 * rim * (x - 1) / 0.25**2


def _uniforms(cells: np.ndarray, salt: int, k: int) -> np.ndarray:
    """k uniforms in [0, 1) per integer cell (... x 3): splitmix64 of the cell and `salt` (... x k)."""
    c = cells.astype(np.int64).view(np.uint64)
    x = (c[..., 0] * np.uint64(0x9E3779B97F4A7C15)) ^ (c[..., 1] * np.uint64(0xC2B2AE3D27D4EB4F))
    x ^= c[..., 2] * np.uint64(0x165667B19E3779F9) ^ np.uint64(salt)
    out = np.empty((*cells.shape[:-1], k))
    for i in range(k):
        x = x + np.uint64(0x9E3779B97F4A7C15)
        z = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        out[..., i] = ((z ^ (z >> np.uint64(31))) >> np.uint64(11)).astype(np.float64) / 2.0**53
    return out


def _pack(cells: np.ndarray) -> np.ndarray:
    """One int64 key per integer cell (N x 3, each coordinate within +-2^20)."""
    c = cells.astype(np.int64) + 2**20
    return (c[:, 0] << 42) | (c[:, 1] << 21) | c[:, 2]


def _cell_craters(bases: np.ndarray, cell: float, octave: int) -> tuple[np.ndarray, ...]:
    """The craters of the 2 x 2 x 2 cells from each base cell (K x 3) of an octave, as one list: base by
    base, in the cells' order (np.ndindex) and each cell's candidates' order, those on the surface's shell
    only. (each base's first crater (K), its crater count (K), centres on the sphere (L x 3, float32),
    radii (L), depths in radii (L), fresh flags (L)). A cell's candidates are drawn once however many
    bases share it."""
    cells = (bases[:, None, :] + np.array(list(np.ndindex(2, 2, 2)))).reshape(-1, 3)  # 8K x 3
    _, first, of_cell = np.unique(_pack(cells), return_index=True, return_inverse=True)
    cells = cells[first]  # U x 3: the distinct cells
    u = _uniforms(cells, MOON_SEED + 131 * octave, 6 * CANDIDATES).reshape(len(cells), CANDIDATES, 6)
    centre = (cells[:, None, :] + u[..., :3]) * cell  # U x CANDIDATES x 3
    radius_3d = np.linalg.norm(centre, axis=-1)
    on_shell = (np.abs(radius_3d - 1) < SHELL * cell).ravel()
    # each base's candidates: cell by cell, CANDIDATES each (K x 8 CANDIDATES), those on the shell kept
    candidate = of_cell.reshape(len(bases), 8, 1) * CANDIDATES + np.arange(CANDIDATES)
    candidate = candidate.reshape(len(bases), -1)
    kept = on_shell[candidate]
    count = kept.sum(axis=1)
    pick = candidate[kept]  # row-major: base by base, in order
    u = u.reshape(-1, 6)[pick]
    centre = (centre.reshape(-1, 3)[pick] / radius_3d.ravel()[pick, None]).astype(np.float32)
    radii = cell * (FINE_RADIUS[0] + (FINE_RADIUS[1] - FINE_RADIUS[0]) * u[:, 3] ** 2)
    return np.cumsum(count) - count, count, centre, radii, 0.1 + 0.25 * u[:, 4], u[:, 5] < 0.15


def _unique_runs(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """np.unique(keys, return_inverse=True), sorting only the runs of equal keys (neighbouring pixels
    mostly share a cell)."""
    starts = np.flatnonzero(np.concatenate([[True], keys[1:] != keys[:-1]]))
    unique, of_run = np.unique(keys[starts], return_inverse=True)
    return unique, np.repeat(of_run, np.diff(np.append(starts, len(keys))))


def _ragged(start: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows i repeated count[i] times, and beside each the entries start[i] .. start[i] + count[i] - 1."""
    row = np.repeat(np.arange(len(count)), count)
    return row, np.arange(len(row)) - np.repeat(np.cumsum(count) - count - start, count)


def fine_craters(q: np.ndarray, footprint: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(slope vectors N x 3, albedo factors N) of the craters smaller than the maps' at selenographic
    unit vectors q seen with `footprint` Moon radii a pixel: the height gradient (tangent to the sphere,
    dimensionless) summed over the octaves the footprint resolves, each faded in by RESOLVED_PX. Depths
    are 0.05-0.18 of the diameter (degraded to fresh simple craters); one in seven is young, with a
    bright floor and ejecta halo.

    A point meets the craters of the 2 x 2 x 2 cells nearest it (from its base cell, floor(q / cell -
    0.5)), those within REACH radii. The half cell a point lies in fixes its base cell, so the points are
    grouped by half cell, and each is tried only against its base's craters that reach the half cell's
    box, in the base's order (the sums add in the same order whatever the grouping)."""
    slope, log_albedo = np.zeros_like(q), np.zeros(len(q))
    for octave in range(FINE_OCTAVES):
        cell = FINE_CELL / 2**octave
        weight = np.clip((cell / footprint - RESOLVED_PX[0]) / (RESOLVED_PX[1] - RESOLVED_PX[0]), 0, 1)
        idx = np.nonzero(weight > 0)[0]
        if len(idx) == 0:
            break  # finer octaves are smaller still
        q_live = q if len(idx) == len(q) else q[idx]
        p = q_live.astype(np.float32)
        unique_half, group = _unique_runs(_pack(np.floor(q_live / (cell / 2))))  # q / cell exactly, doubled
        half = np.stack([(unique_half >> s & (2**21 - 1)) - 2**20 for s in (42, 21, 0)], axis=1)
        base = (half >> 1) - 1 + (half & 1)  # floor(half / 2 - 0.5): the half cell's base cell
        unique_base, base_of = np.unique(_pack(base), return_inverse=True)
        bases = np.stack([(unique_base >> s & (2**21 - 1)) - 2**20 for s in (42, 21, 0)], axis=1)
        start, count, centres, radii, depths, fresh = _cell_craters(bases, cell, octave)
        # each half cell against its base's craters: kept where the crater reaches its box
        g, c = _ragged(start[base_of], count[base_of])
        reach = (REACH * radii[c] + 1e-3 * cell)[:, None]
        lo = half[g] * (cell / 2)
        inside = np.all((centres[c] >= lo - reach) & (centres[c] <= lo + (cell / 2) + reach), axis=1)
        g, c = g[inside], c[inside]
        per_group = np.bincount(g, minlength=len(half))
        pixel, pair = _ragged((np.cumsum(per_group) - per_group)[group], per_group[group])
        k = c[pair]  # each pair's crater
        d = p[pixel] - centres[k]  # from each candidate crater's centre
        x2 = np.einsum("nk,nk->n", d, d) / np.maximum(radii[k], 1e-30) ** 2
        near = np.nonzero(x2 < REACH**2)[0]
        if len(near) == 0:
            continue
        rows, k = pixel[near], k[near]
        x, dh, p_h = np.sqrt(x2[near]), d[near], p[rows]
        tangent = dh - row_dot(dh, p_h)[:, None] * p_h
        tangent /= np.maximum(row_norm(tangent), 1e-12)[:, None]
        w = weight[idx[rows]]
        contribution = (w * crater_profile_slope(x, depths[k]))[:, None] * tangent
        for axis in range(3):
            slope[:, axis] += np.bincount(idx[rows], contribution[:, axis], minlength=len(q))
        young = np.nonzero(fresh[k])[0]  # the others add no halo
        halo = w[young] * np.log1p(0.4 * np.exp(-((x[young] / 1.3) ** 4)))
        log_albedo += np.bincount(idx[rows[young]], halo, minlength=len(q))
    return slope, np.exp(log_albedo)


def moon_surface(
    q: np.ndarray, n: np.ndarray, east: np.ndarray, north: np.ndarray, footprint: np.ndarray, sun: np.ndarray
) -> np.ndarray:
    """The sunlit Moon's reflectance (N: albedo x Lambert's cosine) at selenographic unit vectors q, whose
    camera-frame normals are n with local east and north unit vectors (N x 3 each), seen with `footprint`
    Moon radii a pixel, under the unit `sun` direction (camera frame).

    The normal is tilted by the slopes of the maps and of the fine craters. Where the maps' terrain alone
    faces away from the sun, it shadows what lies on it (a fine crater's sunward wall is not lit in the
    shade of a large crater's wall), fading over the last 3 degrees; past the sphere's terminator, night.
    """
    fine_slope, fine_albedo = fine_craters(q, footprint)
    east_q = np.stack([-q[:, 1], q[:, 0], np.zeros(len(q))], axis=1)  # selenographic east: z x q
    east_q /= np.maximum(row_norm(east_q), 1e-9)[:, None]
    north_q = np.cross(q, east_q)
    albedo, map_north, map_east = equirect(_stacked_maps(), q).T
    s_north = np.clip(map_north + row_dot(fine_slope, north_q), -MAX_SLOPE, MAX_SLOPE)
    s_east = np.clip(map_east + row_dot(fine_slope, east_q), -MAX_SLOPE, MAX_SLOPE)

    def cosine(slope_east: np.ndarray, slope_north: np.ndarray) -> np.ndarray:
        tilted = n - slope_east[:, None] * east - slope_north[:, None] * north
        return (tilted @ sun) / row_norm(tilted)

    terrain = np.clip(cosine(map_east, map_north) / np.sin(np.deg2rad(3.0)), 0, 1)
    lit = np.clip(cosine(s_east, s_north), 0, 1) * terrain * (n @ sun > 0)
    return albedo * fine_albedo * lit
