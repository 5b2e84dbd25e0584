"""The pinhole image the backends render for a camera, and its resampling into the camera's pixels.

A camera with lens distortion or non-square pixels is rendered as a square-pixel pinhole image that
holds every one of its pixels' rays, then resampled through the lens (`to_camera`). Only the image is
resampled: the label maps are ray cast along each pixel's exact ray (CameraSpec.rays), never interpolated.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from scgen.scenes.spec import CameraSpec

MARGIN_PX = 3  # room around the rays for the bilinear footprint


def needs_resampling(camera: CameraSpec) -> bool:
    K = camera.K_mat
    return not camera.pinhole or K[0, 0] != K[1, 1] or K[0, 1] != 0.0


@functools.lru_cache(maxsize=8)
def render_camera(camera: CameraSpec) -> CameraSpec:
    """The square-pixel pinhole camera a backend renders: `camera` itself when it is one; else one at the
    larger focal length whose image holds the ray of every pixel of `camera`."""
    if not needs_resampling(camera):
        return camera
    w, h = camera.width, camera.height
    u, v = np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64)
    edge_u = np.concatenate([u, u, np.full(h, -0.5), np.full(h, w - 0.5)])  # the image's outer edges
    edge_v = np.concatenate([np.full(w, -0.5), np.full(w, h - 0.5), v, v])
    xy = camera.rays(edge_u, edge_v)[:, :2]
    f = float(max(camera.K_mat[0, 0], camera.K_mat[1, 1]))
    lo, hi = xy.min(axis=0) * f - MARGIN_PX, xy.max(axis=0) * f + MARGIN_PX
    size = np.ceil(hi - lo).astype(int) + 1
    cx, cy = -lo
    K = (f, 0.0, float(cx), 0.0, f, float(cy), 0.0, 0.0, 1.0)
    return CameraSpec(int(size[0]), int(size[1]), K, camera.exposure_ev)


@functools.lru_cache(maxsize=8)
def _maps(camera: CameraSpec) -> tuple[np.ndarray, np.ndarray]:
    """Where each pixel of `camera` lies in its render camera's image (cv2.remap maps, float32)."""
    K = render_camera(camera).K_mat
    rays = camera.pixel_rays()
    return (
        (K[0, 0] * rays[..., 0] + K[0, 2]).astype(np.float32),
        (K[1, 1] * rays[..., 1] + K[1, 2]).astype(np.float32),
    )


def to_camera(image: np.ndarray, camera: CameraSpec) -> np.ndarray:
    """The render camera's image (H' x W' x C, linear) resampled bilinearly onto `camera`'s pixels."""
    if not needs_resampling(camera):
        return image
    map_x, map_y = _maps(camera)
    return cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
