"""Procedural background images in linear radiance, deterministic from the background seed.

Both backends render the foreground over a transparent film and composite it over these, so
the backgrounds are the same image whatever the renderer. Kinds: clean (black space, sparse
stars), complex (dense stars, nebula glow, sun glare), earth (lit disc or limb with oceans,
continents, clouds and an atmosphere rim), cluttered (a star field behind 3D clutter props).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from scgen.scenes.spec import SceneSpec


def background_image(spec: SceneSpec, user_dir: Path | None = None) -> np.ndarray:
    """H x W x 3 float32 linear background for this sample."""
    cam = spec.camera
    rng = np.random.default_rng(spec.background.seed)
    kind = spec.background.kind
    if kind == "user":
        return _user_image(spec, user_dir, rng)
    img = _star_field(rng, cam.height, cam.width, n_stars=250 if kind in ("clean", "cluttered") else 2500)
    if kind == "complex":
        img += _nebula(rng, cam.height, cam.width)
        img += _glare(rng, cam.height, cam.width)
    elif kind == "earth":
        img = _earth(spec, rng, img)
    return img.astype(np.float32)


def _star_field(rng: np.random.Generator, h: int, w: int, n_stars: int) -> np.ndarray:
    img = np.zeros((h, w, 3), np.float32)
    ys = rng.integers(0, h, n_stars)
    xs = rng.integers(0, w, n_stars)
    flux = 0.02 * rng.pareto(1.6, n_stars).clip(0, 40) + 0.01
    temperature = rng.uniform(0, 1, n_stars)[:, None]
    colour = (1 - temperature) * np.array([1.0, 0.85, 0.7]) + temperature * np.array([0.75, 0.85, 1.0])
    np.add.at(img, (ys, xs), (flux[:, None] * colour).astype(np.float32))
    return cv2.GaussianBlur(img, (0, 0), 0.6) * 2.0


def _smooth_noise(rng: np.random.Generator, h: int, w: int, octaves: int = 5, base: int = 3) -> np.ndarray:
    """Fractal value noise in [0, 1] (sum of upsampled random grids)."""
    acc = np.zeros((h, w), np.float32)
    amp, total = 1.0, 0.0
    for o in range(octaves):
        n = base * 2**o
        grid = rng.uniform(0, 1, (n, n)).astype(np.float32)
        acc += amp * cv2.resize(grid, (w, h), interpolation=cv2.INTER_CUBIC)
        total += amp
        amp *= 0.5
    acc /= total
    return (acc - acc.min()) / max(1e-6, float(acc.max() - acc.min()))


def _nebula(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    density = _smooth_noise(rng, h, w) ** 3
    hue = rng.uniform(0, 1, 3).astype(np.float32)
    tint = 0.4 + 0.6 * hue / hue.max()
    band = _smooth_noise(rng, h, w, octaves=3, base=2)
    return (0.12 * density[..., None] * tint + 0.03 * band[..., None] * np.array([0.8, 0.8, 1.0])).astype(
        np.float32
    )


def _glare(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """A sun-glare bloom with a faint diffraction streak, anchored near an image edge."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    edge = rng.integers(4)
    cx = [rng.uniform(0, w), rng.uniform(0, w), -0.1 * w, 1.1 * w][edge]
    cy = [-0.1 * h, 1.1 * h, rng.uniform(0, h), rng.uniform(0, h)][edge]
    r = np.hypot(x - cx, y - cy) / max(h, w)
    bloom = 0.6 * np.exp(-r / 0.12) + 0.15 * np.exp(-r / 0.4)
    angle = rng.uniform(0, np.pi)
    dist_line = np.abs((x - cx) * np.sin(angle) - (y - cy) * np.cos(angle)) / max(h, w)
    streak = 0.2 * np.exp(-dist_line / 0.004) * np.exp(-r / 0.5)
    return ((bloom + streak)[..., None] * np.array([1.0, 0.95, 0.85])).astype(np.float32)


def _earth(spec: SceneSpec, rng: np.random.Generator, stars: np.ndarray) -> np.ndarray:
    """A lit Earth disc/limb: the unit sphere at direction c seen with angular radius rho."""
    cam = spec.camera
    params = spec.background.params
    c = np.asarray(params["centre_dir"], np.float64)
    rho = np.deg2rad(params["angular_radius_deg"])
    centre = c / np.sin(rho)  # Earth of radius 1 at this distance subtends rho
    v, u = np.mgrid[0 : cam.height, 0 : cam.width].astype(np.float64)
    rays = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(cam.K_mat).T
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    b = rays @ centre
    disc = b * b - (centre @ centre - 1.0)
    hit = disc > 0
    t_hit = b - np.sqrt(np.where(hit, disc, 0.0))
    normal = rays * t_hit[..., None] - centre
    sun = np.asarray(spec.sun.direction)
    lambert = np.clip(normal @ sun, 0, 1)
    # surface texture from 3D value noise sampled on the sphere (lat/long grids)
    lat = np.arcsin(np.clip(normal[..., 1], -1, 1))
    lon = np.arctan2(normal[..., 0], normal[..., 2])
    tex_h, tex_w = 256, 512
    land = _smooth_noise(rng, tex_h, tex_w, octaves=6, base=4) > 0.55
    cloud = np.clip((_smooth_noise(rng, tex_h, tex_w, octaves=6, base=6) - 0.5) * 3, 0, 1)
    ti = ((lat / np.pi + 0.5) * (tex_h - 1)).astype(int).clip(0, tex_h - 1)
    tj = ((lon / (2 * np.pi) + 0.5) * (tex_w - 1)).astype(int).clip(0, tex_w - 1)
    ocean_c = np.array([0.02, 0.06, 0.18])
    land_c = np.array([0.12, 0.14, 0.06])
    surface = np.where(land[ti, tj][..., None], land_c, ocean_c)
    cl = cloud[ti, tj][..., None]
    surface = (1 - cl) * surface + cl * np.array([0.8, 0.8, 0.82])
    irr = spec.sun.irradiance / 1361.0 * 2.0 ** (-spec.camera.exposure_ev)
    earth = surface * lambert[..., None] * irr
    # atmosphere rim: blue glow growing towards the limb on the day side
    limb = np.clip(1 - np.sqrt(np.clip(disc, 0, None)) / 0.35, 0, 1)
    rim = 0.25 * limb[..., None] * np.array([0.3, 0.55, 1.0]) * (0.2 + lambert[..., None]) * irr
    img = np.where(hit[..., None], earth + rim, stars)
    halo_d = np.clip(-disc, 0, None)
    halo = 0.08 * np.exp(-halo_d / 0.02)[..., None] * np.array([0.3, 0.55, 1.0]) * irr
    return (img + np.where(hit[..., None], 0, halo)).astype(np.float32)


def _user_image(spec: SceneSpec, user_dir: Path | None, rng: np.random.Generator) -> np.ndarray:
    """A random image from the user's folder, cover-resized and cropped, sRGB decoded to linear."""
    files = sorted(p for p in (user_dir or Path()).iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
    img = cv2.imread(str(files[int(rng.integers(len(files)))]), cv2.IMREAD_COLOR)[..., ::-1]
    h, w = spec.camera.height, spec.camera.width
    scale = max(h / img.shape[0], w / img.shape[1])
    img = cv2.resize(img, (int(np.ceil(img.shape[1] * scale)), int(np.ceil(img.shape[0] * scale))))
    y0 = int(rng.integers(0, img.shape[0] - h + 1))
    x0 = int(rng.integers(0, img.shape[1] - w + 1))
    return srgb_to_linear(img[y0 : y0 + h, x0 : x0 + w].astype(np.float32) / 255.0)


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb8(x: np.ndarray) -> np.ndarray:
    """Linear radiance -> 8-bit sRGB (clipped: over-exposure saturates, as a real sensor does)."""
    x = np.clip(x, 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(s * 255.0).astype(np.uint8)
