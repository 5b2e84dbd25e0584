"""Light the lens scatters: bloom around over-exposed pixels, and the sun's disc, ghosts and veiling glare.

Both act on the linear image before the sensor clips it, so a saturated highlight on the target blooms
and the sun flares over the target, whatever the background.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from scgen.render.camera import optics
from scgen.render.conventions import LUMA
from scgen.render.lighting import SOLAR_CONSTANT
from scgen.scenes.config.camera import GlareSettings
from scgen.scenes.spec import CameraSpec, SceneSpec

SUN_ANGULAR_RADIUS = np.deg2rad(0.2666)  # at 1 AU
SUN_SOLID_ANGLE = 2 * np.pi * (1 - np.cos(SUN_ANGULAR_RADIUS))
FLARE_REACH_RAD = np.deg2rad(40.0)  # the sun flares while within this angle of the field of view
FLARE_FALLOFF_RAD = np.deg2rad(10.0)
IN_VIEW_RAD = 1e-6  # the sun's ray meets the image (float rounding of the clamped ray aside)
BLOOM_DOWNSAMPLE = 4  # the wide PSF is smooth: convolve at a quarter of the resolution


@functools.lru_cache(maxsize=8)
def bloom_kernel(radius_px: int, spikes: int) -> np.ndarray:
    """The lens' wide PSF at 1/BLOOM_DOWNSAMPLE scale: a halo falling as 1/r^2 and `spikes` diffraction
    spikes at equal angles (the aperture's and spider vanes' streaks), summing to one."""
    r = max(2, radius_px // BLOOM_DOWNSAMPLE)
    y, x = np.mgrid[-r : r + 1, -r : r + 1].astype(np.float64)
    rho = np.hypot(x, y)
    k = 1.0 / (1.0 + (rho / max(0.05 * r, 0.5)) ** 2)
    for j in range(spikes):
        a = 2 * np.pi * j / spikes
        along = x * np.cos(a) + y * np.sin(a)
        across = np.abs(-x * np.sin(a) + y * np.cos(a))
        k += 0.5 * np.exp(-across / 0.6 - along / (0.5 * r)) * (along >= 0)
    k *= rho <= r
    return (k / k.sum()).astype(np.float32)


def bloom(image: np.ndarray, share: float, radius_px: float, spikes: int) -> np.ndarray:
    """Spread `share` of the light above saturation (image value 1) through the wide PSF."""
    if share <= 0 or image.max() <= 1.0:  # nothing above saturation (one cheap pass; NaN goes on)
        return image
    excess = np.maximum(image - 1.0, 0.0)
    if not excess.any():
        return image
    h, w = image.shape[:2]
    small = cv2.resize(excess, (max(1, w // BLOOM_DOWNSAMPLE), max(1, h // BLOOM_DOWNSAMPLE)),
                       interpolation=cv2.INTER_AREA)  # fmt: skip
    halo = cv2.filter2D(small, -1, bloom_kernel(int(radius_px), spikes), borderType=cv2.BORDER_CONSTANT)
    halo = cv2.resize(halo, (w, h), interpolation=cv2.INTER_LINEAR).reshape(image.shape)
    return image + share * halo


@dataclass(frozen=True)
class SunView:
    """Where the sun is for the camera: angle from the field of view (0 inside) and pixel position."""

    off_view_rad: float
    pixel: np.ndarray  # (u, v), through the lens; meaningful when in view
    in_view: bool


def sun_view(camera: CameraSpec, sun_dir: np.ndarray) -> SunView | None:
    """The sun's place relative to the image; None when it is behind the camera's image plane."""
    if sun_dir[2] <= 0:
        return None
    K = camera.K_mat
    pin = K @ (sun_dir / sun_dir[2])
    u, v = np.clip(pin[0], 0, camera.width - 1), np.clip(pin[1], 0, camera.height - 1)
    nearest = camera.rays(np.array([u]), np.array([v]))[0]
    off = float(np.arccos(np.clip(nearest @ sun_dir / np.linalg.norm(nearest), -1.0, 1.0)))
    if off > IN_VIEW_RAD:
        return SunView(off, pin[:2], False)
    pixel = camera.project(sun_dir[None])[0]
    inside = bool(0 <= pixel[0] <= camera.width - 1 and 0 <= pixel[1] <= camera.height - 1)
    return SunView(0.0, pixel, inside)


def sun_flare(image: np.ndarray, spec: SceneSpec, instance: np.ndarray, ev_total: float,
              glare: GlareSettings, rng: np.random.Generator) -> tuple[np.ndarray, bool]:  # fmt: skip
    """The sun's disc (where it is seen past every object), veiling glare and ghosts along the line from
    the sun's image through the principal point, all scaled by the sun's irradiance and the exposure.
    Returns the image and whether a flare was drawn."""
    camera = spec.camera
    s = np.asarray(spec.sun.direction, np.float64)
    view = sun_view(camera, s)
    if not glare.flare or view is None or view.off_view_rad > FLARE_REACH_RAD or spec.sun.irradiance <= 0:
        return image, False  # (no irradiance: a sequence's frame in eclipse, the sun behind the Earth)
    plate = spec.sun.irradiance / SOLAR_CONSTANT * 2.0 ** (-ev_total)  # value of a white plate facing it
    h, w = image.shape[:2]
    y, x = optics.pixel_grid(camera)
    seen = 1.0
    if view.in_view:
        r_px = camera.K_mat[0, 0] * np.tan(SUN_ANGULAR_RADIUS)
        disc = np.hypot(x - view.pixel[0], y - view.pixel[1]) <= max(r_px, 0.5)
        if not disc.any():
            disc[int(round(view.pixel[1])), int(round(view.pixel[0]))] = True
        clear = disc & (instance == 0)
        seen = float(clear.sum() / disc.sum())
        sun_value = plate * np.pi / SUN_SOLID_ANGLE * min(1.0, np.pi * r_px**2 / disc.sum())
        image = image.copy()
        image[clear] += np.float32(sun_value)
    near = float(np.exp(-view.off_view_rad / FLARE_FALLOFF_RAD)) * seen
    if near < 1e-3:
        return image, False
    K = camera.K_mat
    flux = plate * np.pi * K[0, 0] * K[1, 1] * near  # the sun's light on the sensor (image value x px)
    diag = float(np.hypot(w, h))
    r = np.hypot(x - view.pixel[0], y - view.pixel[1]) / diag
    profile = 0.1 + np.exp(-r / 0.15)  # a uniform floor and a glow around the sun's image
    veil = glare.veiling_glare * flux / (w * h) * profile / profile.mean()
    image = image + _tint(veil, image.shape[-1], np.array([1.0, 0.97, 0.9]))
    centre = K[:2, 2]
    for _ in range(int(rng.integers(glare.flare_ghosts[0], glare.flare_ghosts[1] + 1))):
        at = centre + rng.uniform(-1.6, 0.9) * (view.pixel - centre)
        radius = rng.uniform(0.01, 0.08) * diag
        turn, share = rng.uniform(0, np.pi / 3), rng.uniform(*glare.ghost_share)
        colour = rng.uniform(0.5, 1.0, 3)
        x0, y0 = np.clip(np.floor(at - radius - 2).astype(int), 0, [w, h])
        x1, y1 = np.clip(np.ceil(at + radius + 3).astype(int), 0, [w, h])
        if x1 <= x0 or y1 <= y0:
            continue
        gy, gx = y[y0:y1, x0:x1], x[y0:y1, x0:x1]
        edge = np.clip((radius - _hexagon_distance(gx - at[0], gy - at[1], turn)) / 2.0, 0, 1)
        image[y0:y1, x0:x1] += _tint(share * flux / (np.pi * radius**2) * edge, image.shape[-1], colour)
    return image.astype(np.float32), True


def _hexagon_distance(dx: np.ndarray, dy: np.ndarray, turn: float) -> np.ndarray:
    """Distance measure whose level sets are regular hexagons (a six-bladed aperture's ghost)."""
    angles = turn + np.arange(6) * np.pi / 3
    return np.max([dx * np.cos(a) + dy * np.sin(a) for a in angles], axis=0) / np.cos(np.pi / 6)


def _tint(plane: np.ndarray, channels: int, colour: np.ndarray) -> np.ndarray:
    """An H x W light plane as H x W x C: coloured for RGB, its luminance for one channel."""
    if channels == 1:
        return (plane * float(colour @ LUMA))[..., None].astype(np.float32)
    return (plane[..., None] * colour).astype(np.float32)
