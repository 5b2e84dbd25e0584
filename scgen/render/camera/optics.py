"""The lens and the exposure time in the image plane: vignetting, lateral colour, PSF and motion blur.

Each works on a linear H x W x C float32 image and keeps its total light (the blur kernels sum to one).
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from scgen.scenes.spec import CameraSpec

FWHM_PER_SIGMA = 2.0 * np.sqrt(2.0 * np.log(2.0))
SUBSAMPLES = 8  # per pixel and axis, for the anti-aliased disc and line kernels


@functools.lru_cache(maxsize=8)
def pixel_grid(camera: CameraSpec) -> np.ndarray:
    """(v, u) pixel-centre coordinates of the camera's image, float32 2 x H x W (read-only, shared)."""
    grid = np.mgrid[0 : camera.height, 0 : camera.width].astype(np.float32)
    grid.flags.writeable = False
    return grid


@functools.lru_cache(maxsize=8)
def _radius2(camera: CameraSpec) -> np.ndarray:
    """Squared distance of each pixel from the principal point, 1 at the farthest corner (H x W)."""
    K = camera.K_mat
    v, u = pixel_grid(camera)
    r2 = (u - K[0, 2]) ** 2 + (v - K[1, 2]) ** 2
    return (r2 / r2.max()).astype(np.float32)


def vignette(image: np.ndarray, camera: CameraSpec, strength: float) -> np.ndarray:
    """Radial fall-off 1 - strength * rho^2 (rho: distance from the principal point, 1 at the far corner)."""
    if strength <= 0:
        return image
    return image * (1.0 - strength * _radius2(camera))[..., None]


def lateral_colour(image: np.ndarray, camera: CameraSpec, shift_px: float) -> np.ndarray:
    """Lateral chromatic aberration: red magnified and blue shrunk about the principal point, each moved
    by `shift_px` at the farthest corner (green stays)."""
    if shift_px <= 0 or image.shape[-1] != 3:
        return image
    K = camera.K_mat
    cx, cy = K[0, 2], K[1, 2]
    v, u = pixel_grid(camera)
    reach = max(np.hypot(x - cx, y - cy) for x in (0, camera.width - 1) for y in (0, camera.height - 1))
    out = image.copy()
    for channel, sign in ((0, 1.0), (2, -1.0)):
        scale = 1.0 + sign * shift_px / reach  # the channel's image is `scale` times larger: sample inwards
        map_x = ((u - cx) / scale + cx).astype(np.float32, copy=False)
        map_y = ((v - cy) / scale + cy).astype(np.float32, copy=False)
        out[..., channel] = cv2.remap(image[..., channel], map_x, map_y, cv2.INTER_LINEAR,
                                      borderMode=cv2.BORDER_REPLICATE)  # fmt: skip
    return out


def psf_blur(image: np.ndarray, kind: str, fwhm_px: float) -> np.ndarray:
    """The optics' point-spread function: a Gaussian of this FWHM, or a uniform disc of this diameter."""
    if fwhm_px <= 0:
        return image
    if kind == "gaussian":
        return _keep_shape(cv2.GaussianBlur(image, (0, 0), fwhm_px / FWHM_PER_SIGMA), image)
    return convolve(image, disc_kernel(round(fwhm_px, 3)))


def motion_blur(image: np.ndarray, length_px: float, angle_deg: float) -> np.ndarray:
    """Motion during the exposure: a line of this length and direction, anti-aliased."""
    if length_px <= 0:
        return image
    return convolve(image, line_kernel(round(length_px, 3), round(angle_deg, 2)))


def convolve(image: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    return _keep_shape(cv2.filter2D(image, -1, kernel, borderType=cv2.BORDER_REFLECT), image)


def _keep_shape(out: np.ndarray, like: np.ndarray) -> np.ndarray:
    """OpenCV drops a trailing channel axis of size 1: put it back."""
    return out.reshape(like.shape)


@functools.lru_cache(maxsize=32)
def disc_kernel(diameter_px: float) -> np.ndarray:
    """A uniform disc of this diameter, area-sampled, summing to one."""
    half = int(np.ceil(diameter_px / 2)) + 1
    n = (2 * half + 1) * SUBSAMPLES
    s = (np.arange(n) + 0.5) / SUBSAMPLES - (half + 0.5)
    inside = (s[:, None] ** 2 + s[None, :] ** 2) <= (diameter_px / 2) ** 2
    k = inside.reshape(2 * half + 1, SUBSAMPLES, 2 * half + 1, SUBSAMPLES).mean(axis=(1, 3))
    if k.sum() == 0:
        k[half, half] = 1.0
    return (k / k.sum()).astype(np.float32)


@functools.lru_cache(maxsize=64)
def line_kernel(length_px: float, angle_deg: float) -> np.ndarray:
    """A straight line of this length through the centre, bilinearly splatted, summing to one."""
    half = int(np.ceil(length_px / 2)) + 1
    k = np.zeros((2 * half + 1, 2 * half + 1), np.float64)
    steps = max(2, int(np.ceil(length_px * SUBSAMPLES)))
    t = np.linspace(-length_px / 2, length_px / 2, steps)
    a = np.deg2rad(angle_deg)
    x, y = half + t * np.cos(a), half + t * np.sin(a)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    for dy, wy in ((0, 1 - fy), (1, fy)):
        for dx, wx in ((0, 1 - fx), (1, fx)):
            np.add.at(k, (y0 + dy, x0 + dx), wx * wy)
    return (k / k.sum()).astype(np.float32)
