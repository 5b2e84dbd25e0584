"""Procedural background images in linear radiance, deterministic from the background seed.

Both backends render the foreground over a transparent film and composite it over these, so
the backgrounds are the same image whatever the renderer. Kinds:
- clean: black space with a sparse, faint star field;
- complex: the sunlit Moon seen from lunar orbit (its cratered limb) or from afar (a disc), over the stars;
- earth: a lit Earth limb or disc (oceans with sun glint, continents, ice, clouds, atmosphere rim);
- cluttered: a moderate star field (the clutter itself is 3D props, rendered by the backend);
- user: an image of the user's own (the sampler picks the file), cover-cropped, sRGB decoded.
The sun's glare is the camera stage's (scgen.render.camera.glare), over the whole image.
Sunlit things (the Earth) follow the camera model of scgen.render.lighting: they scale with the
sun irradiance and the exposure; so does the Moon (scgen.render.sky.moon_surface). The procedural stars only
scale with exposure and are exaggerated for visibility (real stars, the Hipparcos default, are about 1e-8
of a sunlit plate): nothing else in the sky glows.
"""

from __future__ import annotations

import cv2
import numpy as np

from scgen.errors import ScgenError
from scgen.render.lighting import exposure_scale
from scgen.render.sky.bluemarble import level_of_detail
from scgen.render.sky.earth_surface import bluemarble_surface, procedural_surface
from scgen.render.sky.moon_surface import moon_surface
from scgen.render.sky.rows import row_dot, row_norm
from scgen.render.sky.stars import star_image
from scgen.scenes.geometry import random_rotation, unit_sphere_hits
from scgen.scenes.sky import body_centre, earth_frame, sky_frame
from scgen.scenes.spec import SceneSpec

STARS_PER_MEGAPIXEL = {"clean": 150, "earth": 150, "cluttered": 600, "complex": 150}
MOON_TINT = np.array([1.06, 1.0, 0.9])  # the Moon's reddish grey, unit luminance
SKY_BLUE = np.array([0.22, 0.45, 1.0])  # atmosphere scattering colour
# the glow above the Earth's limb is drawn out to where it falls below GLOW_FLOOR of a sunlit white plate
GLOW_FLOOR = 1e-12
GLINT_FROM = 0.98  # the glint is drawn where the half angle's cosine exceeds this (0.98^2000 = 3e-18)


def background_image(spec: SceneSpec) -> np.ndarray:
    """H x W x 3 float32 linear background for this sample."""
    cam = spec.camera
    rng = np.random.default_rng(spec.background.seed)
    kind = spec.background.kind
    if kind == "user":
        return _user_image(spec, rng)
    gain = 2.0 ** (-cam.exposure_ev)
    params = spec.background.params
    if params.get("stars") == "hipparcos":
        img = star_image(cam, sky_frame(params), params["stars_boost_ev"])
    else:
        density = STARS_PER_MEGAPIXEL[kind] * cam.width * cam.height / 1e6
        img = _star_field(rng, cam.height, cam.width, int(density)) * gain
    if kind == "complex":
        img = _moon(spec, rng, cam.pixel_directions(), img)
    elif kind == "earth":
        img = _earth(spec, rng, cam.pixel_directions(), img)
    return img.astype(np.float32, copy=False)


def _star_field(rng: np.random.Generator, h: int, w: int, n_stars: int) -> np.ndarray:
    """Point stars with a power-law flux distribution and black-body-like tints, blurred by the optics."""
    img = np.zeros((h, w, 3), np.float32)
    ys = rng.uniform(0, h - 1, n_stars)
    xs = rng.uniform(0, w - 1, n_stars)
    flux = 0.015 * (rng.pareto(1.4, n_stars) + 0.3).clip(0, 60)
    temperature = rng.uniform(0, 1, n_stars)[:, None]
    colour = (1 - temperature) * np.array([1.0, 0.8, 0.62]) + temperature * np.array([0.72, 0.84, 1.0])
    value = (flux[:, None] * colour).astype(np.float32)
    # bilinear splat: sub-pixel positions, so faint stars are not all single hot pixels
    x0, y0 = np.floor(xs).astype(int), np.floor(ys).astype(int)
    fx, fy = (xs - x0)[:, None], (ys - y0)[:, None]
    for dy, wy in ((0, 1 - fy), (1, fy)):
        for dx, wx in ((0, 1 - fx), (1, fx)):
            np.add.at(img, (np.minimum(y0 + dy, h - 1), np.minimum(x0 + dx, w - 1)), value * wx * wy)
    return cv2.GaussianBlur(img, (0, 0), 0.7) * 3.0


def _moon(spec: SceneSpec, rng: np.random.Generator, rays: np.ndarray, stars: np.ndarray) -> np.ndarray:
    """The sunlit Moon: the unit sphere at direction c seen with angular radius rho, over the stars.

    Lambertian under the sun with the map's albedo and the craters' and relief's slopes; the terminator
    is the sphere's own, so slopes tilt light within the day side only. Airless: no haze, no glow.
    """
    centre = body_centre(spec.background.params)
    hit, n, _, _ = unit_sphere_hits(rays, centre)
    turn = random_rotation(rng)  # camera -> selenographic: each sample sees another part of the Moon
    east = np.cross(turn[2], n)  # turn[2]: the Moon's north pole in the camera frame
    east /= np.maximum(row_norm(east), 1e-9)[:, None]
    footprint = _footprint(spec, n, rays[hit], centre)
    sun = np.asarray(spec.sun.direction)
    reflectance = moon_surface(n @ turn.T, n, east, np.cross(n, east), footprint, sun)
    img = stars.astype(np.float32)  # a copy: the caller's image stays as it was
    img[hit] = spec.sun.irradiance * exposure_scale(spec) * reflectance[:, None] * MOON_TINT
    return img


def _footprint(spec: SceneSpec, n: np.ndarray, rays: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Arc of the unit sphere at `centre` (body radii, radians) a pixel spans where its rays hit at normals
    n: the distance over the focal length, stretched by the obliquity's square root (the geometric mean of
    the footprint's two sides)."""
    mu_v = np.maximum(-row_dot(n, rays), 1e-3)
    return row_norm(n + centre) / spec.camera.focal / np.sqrt(mu_v)


def _earth(spec: SceneSpec, rng: np.random.Generator, rays: np.ndarray, stars: np.ndarray) -> np.ndarray:
    """A lit Earth: the unit sphere at direction c seen with angular radius rho, over the star field.

    Lambertian surface (scgen.render.sky.earth_surface: Blue Marble or procedural, with clouds; oceans
    with a sun glint) under the sun, a scattering haze thickening towards the limb, and a thin glow
    above it; night side black.
    """
    params = spec.background.params
    centre = body_centre(params)
    hit, n, b, disc = unit_sphere_hits(rays, centre)  # n: unit surface normals
    sun = np.asarray(spec.sun.direction)
    irr = spec.sun.irradiance * exposure_scale(spec)  # image value of a white plate facing the sun

    mu_s = n @ sun
    rays_hit = rays[hit]
    mu_v = -row_dot(n, rays_hit)  # cosine of the viewing angle (1 at disc centre, 0 at limb)
    if params.get("earth_map") == "bluemarble":
        q = n @ earth_frame(params).T  # Earth-fixed coordinates: z the north pole, x Greenwich
        footprint = _footprint(spec, n, rays_hit, centre)
        surface, water, cloud = bluemarble_surface(q, level_of_detail(footprint), spec.background.seed)
    else:
        q = n @ random_rotation(rng).T  # continents do not follow the camera
        surface, water, cloud = procedural_surface(rng, q)
    lit = np.clip(mu_s, 0, 1)[:, None]
    half = sun - rays_hit
    half /= row_norm(half)[:, None]
    # the sun's glint: cos^2000 of the half angle, taken where it can show (GLINT_FROM^2000 = 3e-18)
    cos_half = row_dot(n, half)
    sharp = np.zeros(len(cos_half))
    near = cos_half > GLINT_FROM
    sharp[near] = np.minimum(cos_half[near], 1) ** 2000
    glint = 0.15 * water * (1 - cloud) * sharp[:, None]
    haze_depth = 1.0 / np.maximum(mu_v, 0.08)  # optical path through the atmosphere grows to the limb
    haze = 0.035 * haze_depth[:, None] * SKY_BLUE * np.clip(mu_s + 0.15, 0, 1)[:, None]
    radiance = (surface * lit + glint * (mu_s > 0)[:, None]) * np.exp(-0.05 * haze_depth)[:, None] + haze

    img = stars.astype(np.float32)  # a copy: the caller's image stays as it was
    img[hit] = irr * radiance
    # glow above the limb: thin shell of scattered light on the day side, drawn where it is above
    # GLOW_FLOOR (gap < reach), not over the whole sky
    reach = 0.025 * np.log(0.12 / GLOW_FLOOR)
    outside = ~hit & (disc > -(reach**2))
    gap = np.sqrt(-disc[outside])  # grows with angular distance outside the limb
    limb_normal = rays[outside] * b[outside][:, None] - centre
    limb_normal /= np.maximum(row_norm(limb_normal), 1e-9)[:, None]
    day = np.clip(limb_normal @ sun + 0.2, 0, 1)
    glow = 0.12 * np.exp(-gap / 0.025) * day
    img[outside] += irr * glow[:, None] * SKY_BLUE
    return img


def _user_image(spec: SceneSpec, rng: np.random.Generator) -> np.ndarray:
    """The sampled user image, cover-resized and cropped at random, sRGB decoded to linear.

    Photographs are display-referred: they are used as they are, not scaled by the exposure.
    """
    path = spec.background.params["image"]
    img = cv2.imread(path, cv2.IMREAD_COLOR)
    if img is None:
        raise ScgenError(f"cannot read background image {path}")
    img = img[..., ::-1]
    h, w = spec.camera.height, spec.camera.width
    scale = max(h / img.shape[0], w / img.shape[1])
    size = (max(w, int(np.ceil(img.shape[1] * scale))), max(h, int(np.ceil(img.shape[0] * scale))))
    img = cv2.resize(img, size, interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
    y0 = int(rng.integers(0, img.shape[0] - h + 1))
    x0 = int(rng.integers(0, img.shape[1] - w + 1))
    return srgb_to_linear(img[y0 : y0 + h, x0 : x0 + w].astype(np.float32) / 255.0)


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)
