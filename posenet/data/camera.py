"""The user's camera, and the one warp that shows its image as the training camera would have seen it.

A pose network learns its camera: the RoI's image coordinates (roi_coord2d, normalised by the training
image size) and SITE's depth (z / resize_ratio, in training pixels) carry the training K. An image from
another camera is therefore re-sampled, once, into a *virtual* camera with the training intrinsics and
image size that sits where the user's camera sits and looks where it looks. Both cameras share their
frame, so a pose found in the virtual image is the pose in the user's camera, with nothing to convert.
The same warp removes lens distortion (OpenCV's 5 coefficients) and changes focal length and size.

A user camera with a longer focal length than the training one is first shrunk with pixel-area averaging
(cv2.INTER_AREA), so the re-sampling never skips pixels (no aliasing); a shorter one is up-sampled
bilinearly. Where the virtual image sees past the user's frame it is black, as renders are off-target.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from posenet.errors import PosenetError

DIST_COEFFS = 5  # OpenCV's k1, k2, p1, p2, k3
# a camera without a size (inline numbers, a bare K) fits an image whose centre its principal point lies
# within this share of the image's width and height of: calibrated cameras sit within a few per cent,
# while a camera meant for an image 1.7x larger or smaller than the one given misses by more
CENTRE_SPAN = 0.2


class CameraMismatch(PosenetError):
    """An image that cannot go through the given camera: one input's error (predict records it and goes
    on), not the run's."""


@dataclass(frozen=True)
class Camera:
    """Pinhole intrinsics K (pixels, OpenCV's frame, pixel centres at integers), OpenCV distortion
    (k1, k2, p1, p2, k3; zeros: none) and the image size (width, height; None: taken from each image)."""

    K: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: np.zeros(DIST_COEFFS))
    size: tuple[int, int] | None = None

    @property
    def distorted(self) -> bool:
        return bool(np.any(self.dist != 0))

    def for_image(self, size: tuple[int, int]) -> Camera:
        """This camera for an image of `size` (width, height). A camera with a size takes its own size, or
        a smaller one of its aspect ratio: the image was scaled down, so K scales with it (resized; the
        lens' coefficients act on normalised coordinates and stay). A larger image or another aspect
        ratio is another camera's (or a crop's). A camera without a size takes an image whose centre
        lies near its principal point (CENTRE_SPAN). Refused: CameraMismatch."""
        w, h = int(size[0]), int(size[1])
        if self.size is None:
            off = max(abs(self.K[0, 2] - (w - 1) / 2) / w, abs(self.K[1, 2] - (h - 1) / 2) / h)
            if off > CENTRE_SPAN:
                raise CameraMismatch(
                    f"the image is {w}x{h} but the camera's principal point ({self.K[0, 2]:g}, "
                    f"{self.K[1, 2]:g}) lies {off:.0%} of it from its centre (at most {CENTRE_SPAN:.0%}): "
                    f"a camera for about {2 * self.K[0, 2] + 1:.0f}x{2 * self.K[1, 2] + 1:.0f} images"
                )
            return Camera(self.K, self.dist, (w, h))
        W, H = self.size
        if (w, h) == (W, H):
            return self
        # scaled down by some s with round(W s) = w and round(H s) = h: the two intervals of s overlap
        same_aspect = max((w - 0.5) / W, (h - 0.5) / H) <= min((w + 0.5) / W, (h + 0.5) / H)
        if w <= W and h <= H and same_aspect:
            return resized(self, (w, h))
        why = "larger than the camera's images" if same_aspect else "another aspect ratio"
        raise CameraMismatch(f"the image is {w}x{h} but the camera is for {W}x{H} ({why})")

    def same_as(self, other: Camera) -> bool:
        """Whether the two take the same picture (the warp between them is the identity)."""
        return (
            self.size == other.size
            and np.allclose(self.K, other.K, rtol=0, atol=1e-9)
            and np.allclose(self.dist, other.dist, rtol=0, atol=1e-12)
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "K": self.K.tolist(),
            "dist": self.dist.tolist(),
            "size": list(self.size) if self.size else None,
        }

    @staticmethod
    def from_dict(d: dict[str, Any]) -> Camera:
        size = d.get("size")
        return make_camera(np.asarray(d["K"], float), d.get("dist"), tuple(size) if size else None)


def make_camera(K: np.ndarray, dist: Any = None, size: tuple[int, int] | None = None) -> Camera:
    """A checked Camera: K 3x3 with positive focal lengths, 0, 4, 5 (or more, zero past the fifth)
    distortion coefficients."""
    K = np.asarray(K, dtype=np.float64).reshape(3, 3)
    if not np.all(np.isfinite(K)):
        raise PosenetError(f"camera intrinsics must be finite numbers, got fx={K[0, 0]} fy={K[1, 1]} "
                           f"cx={K[0, 2]} cy={K[1, 2]}")  # fmt: skip
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise PosenetError(f"camera focal lengths must be positive, got fx={K[0, 0]} fy={K[1, 1]}")
    d = np.zeros(DIST_COEFFS)
    given = np.asarray(dist if dist is not None else [], dtype=np.float64).ravel()
    if not np.all(np.isfinite(given)):
        raise PosenetError(f"camera distortion must be finite numbers, got {given.tolist()}")
    if len(given) > DIST_COEFFS and np.any(given[DIST_COEFFS:] != 0):
        raise PosenetError(f"camera distortion: only OpenCV's 5 coefficients are supported, got {len(given)}")
    d[: min(len(given), DIST_COEFFS)] = given[:DIST_COEFFS]
    if size is not None and (size[0] <= 0 or size[1] <= 0):
        raise PosenetError(f"camera image size must be positive, got {size[0]}x{size[1]}")
    return Camera(K, d, (int(size[0]), int(size[1])) if size is not None else None)


def intrinsics(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def parse_inline(text: str) -> Camera:
    """'fx,fy,cx,cy' or 'fx,fy,cx,cy,k1,k2,p1,p2[,k3]' (pixels; OpenCV's distortion)."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError as exc:
        raise PosenetError(f"--camera '{text}' is not fx,fy,cx,cy[,k1,k2,p1,p2,k3] numbers") from exc
    if len(values) not in (4, 8, 9):
        raise PosenetError(f"--camera '{text}' needs 4 numbers (fx,fy,cx,cy), or 8-9 with distortion")
    return make_camera(intrinsics(*values[:4]), values[4:])


def read_camera_file(path: Path) -> Camera:
    """A SPEED+ camera.json (cameraMatrix, distCoeffs, Nu, Nv) or a BOP camera.json (fx, fy, cx, cy,
    width, height; scgen's adds cam_dist)."""
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PosenetError(f"cannot read camera file {path}: {exc}") from exc
    try:
        if "cameraMatrix" in d:  # SPEED+
            return make_camera(
                np.asarray(d["cameraMatrix"], float), d.get("distCoeffs"), (int(d["Nu"]), int(d["Nv"]))
            )
        if "fx" in d and "cx" in d:  # BOP
            size = (int(d["width"]), int(d["height"])) if "width" in d else None
            return make_camera(intrinsics(d["fx"], d["fy"], d["cx"], d["cy"]), d.get("cam_dist"), size)
    except (KeyError, TypeError, ValueError) as exc:
        raise PosenetError(f"camera file {path} is malformed: {exc}") from exc
    raise PosenetError(
        f"camera file {path} is neither SPEED+'s (cameraMatrix, distCoeffs) nor BOP's (fx, cx)"
    )


def shrink_factor(user: Camera, train: Camera) -> float:
    """How many user pixels one training pixel spans (> 1: the user's image is finer)."""
    return float(np.sqrt(user.K[0, 0] * user.K[1, 1] / (train.K[0, 0] * train.K[1, 1])))


def resized(camera: Camera, size: tuple[int, int]) -> Camera:
    """The camera of its image resized to `size` (pixel centres at integers: u' = (u + 0.5) s - 0.5)."""
    assert camera.size is not None
    sx, sy = size[0] / camera.size[0], size[1] / camera.size[1]
    A = np.array([[sx, 0.0, 0.5 * sx - 0.5], [0.0, sy, 0.5 * sy - 0.5], [0.0, 0.0, 1.0]])
    return Camera(A @ camera.K, camera.dist, size)


def warp_maps(user: Camera, train: Camera) -> tuple[np.ndarray, np.ndarray]:
    """cv2.remap maps: for each pixel of the training camera's image, where the user camera sees its ray."""
    assert train.size is not None
    w, h = train.size
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    rays = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], 1) @ np.linalg.inv(train.K).T
    pixels, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), user.K, user.dist)
    pixels = pixels.reshape(h, w, 2).astype(np.float32)
    return pixels[..., 0], pixels[..., 1]


_WARP_MAPS: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}  # a video or folder keeps one camera
_WARP_MAPS_KEPT = 8


def _cached_warp_maps(user: Camera, train: Camera) -> tuple[np.ndarray, np.ndarray]:
    """warp_maps, computed once per pair of cameras (30-40 ms a 320x240 image on 2 cores: most of a
    frame's time at 640x480 before)."""
    parts = [
        np.asarray(c.K, np.float64).tobytes() + np.asarray(c.dist, np.float64).tobytes()
        for c in (user, train)
    ]
    key = b"|".join([*parts, repr((user.size, train.size)).encode()])
    if key not in _WARP_MAPS:
        if len(_WARP_MAPS) >= _WARP_MAPS_KEPT:
            _WARP_MAPS.clear()
        _WARP_MAPS[key] = warp_maps(user, train)
    return _WARP_MAPS[key]


def to_training_camera(image: np.ndarray, user: Camera, train: Camera) -> np.ndarray:
    """`image` (taken by `user`, at its size) as the training camera would have recorded it from the same
    place; the image itself when the two cameras are the same."""
    user = user.for_image((image.shape[1], image.shape[0]))
    if user.same_as(train):
        return image
    s = shrink_factor(user, train)
    if s > 1.0:  # average before sampling: one training pixel covers s x s user pixels
        size = (max(1, round(image.shape[1] / s)), max(1, round(image.shape[0] / s)))
        image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
        user = resized(user, size)
    mx, my = _cached_warp_maps(user, train)
    return cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def map_box(
    box: tuple[float, float, float, float], src: Camera, dst: Camera
) -> tuple[float, float, float, float]:
    """A box [x, y, w, h] of `src`'s image as the box around its outline in `dst`'s image (same place,
    same view direction; the outline's rays go through both lenses)."""
    if src.same_as(dst):
        return tuple(float(v) for v in box)  # type: ignore[return-value]
    x, y, w, h = box
    s = np.linspace(0.0, 1.0, 16)
    left, top, right, bottom = x - 0.5, y - 0.5, x + w - 0.5, y + h - 0.5  # pixel edges
    u = np.concatenate(
        [left + (right - left) * s, np.full(16, right), left + (right - left) * s, np.full(16, left)]
    )
    v = np.concatenate(
        [np.full(16, top), top + (bottom - top) * s, np.full(16, bottom), top + (bottom - top) * s]
    )
    normalised = cv2.undistortPoints(np.stack([u, v], 1).reshape(-1, 1, 2), src.K, src.dist).reshape(-1, 2)
    rays = np.concatenate([normalised, np.ones((len(normalised), 1))], 1)
    pixels, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), dst.K, dst.dist)
    (x0, y0), (x1, y1) = pixels.reshape(-1, 2).min(0), pixels.reshape(-1, 2).max(0)
    return float(x0 + 0.5), float(y0 + 0.5), float(x1 - x0), float(y1 - y0)


def project(points: np.ndarray, R: np.ndarray, t: np.ndarray, camera: Camera) -> np.ndarray:
    """Pixels (N x 2) of model points (N x 3) at pose (R, t) through the camera's lens."""
    rvec, _ = cv2.Rodrigues(np.asarray(R, np.float64))
    uv, _ = cv2.projectPoints(
        np.asarray(points, np.float64), rvec, np.asarray(t, np.float64), camera.K, camera.dist
    )
    return uv.reshape(-1, 2)


def training_camera(Ks: list[np.ndarray], size: tuple[int, int]) -> tuple[Camera, bool]:
    """The camera a network was trained with: the most common K of its training images (rendered
    datasets have one), and whether every image had it."""
    keys = [tuple(np.round(np.asarray(K, np.float64).ravel(), 9)) for K in Ks]
    common = max(set(keys), key=keys.count)
    return make_camera(np.array(common).reshape(3, 3), None, size), len(set(keys)) == 1
