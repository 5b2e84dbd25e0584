"""The Hipparcos 2 stars at their true brightness and colour, imaged by the sample's camera.

Photometry follows the camera model of scgen.render.lighting (image value 1.0: a white Lambertian
plate under the 1-AU sun at EV 0). A star of magnitude m gives the irradiance E = E_sun * 10^(-0.4 (m -
SUN_V)); spread over the solid angle of the pixel it lands in, it is the radiance E / omega, and a
white plate's radiance is E_sun / pi, so the star adds pi * 10^(-0.4 (m - SUN_V)) / omega * 2^-EV to
the image, shared between four pixels by its sub-pixel position (flux-conserving, no blur: the camera
stage adds the optics). Hipparcos' Hp magnitude stands for V (they differ by about 0.1 mag). At 600 px
focal length a 0-mag star is about 2e-5 of a sunlit plate, so at exposures that suit a sunlit target
the sky is black, as in real images; background.stars_boost_ev brightens the stars for users who want
them visible. Colours are black bodies at the temperature of the star's B-V (Ballesteros 2012),
relative to the Sun's (the sun is white in this camera model), at the same V (green) flux.
"""

from __future__ import annotations

import numpy as np

from scgen.scenes.geometry import project
from scgen.scenes.sky_data import hipparcos
from scgen.scenes.spec import CameraSpec

SUN_V, SUN_BV = -26.74, 0.65
RGB_WAVELENGTHS_M = np.array([610e-9, 550e-9, 465e-9])  # effective wavelengths of the R, G, B channels
PLANCK_C2 = 1.4388e-2  # h c / k, m K


def temperature_of_bv(bv: np.ndarray) -> np.ndarray:
    """Black-body temperature (K) of a star of colour index B-V (Ballesteros 2012)."""
    bv = np.clip(bv, -0.4, 2.0)
    return 4600.0 * (1.0 / (0.92 * bv + 1.7) + 1.0 / (0.92 * bv + 0.62))


def tint(bv: np.ndarray) -> np.ndarray:
    """Linear RGB (N x 3) of stars of colour `bv` relative to the Sun's, normalised to G = 1."""

    def planck(t: np.ndarray) -> np.ndarray:  # spectral radiance up to a constant, N x 3
        return RGB_WAVELENGTHS_M**-5 / np.expm1(PLANCK_C2 / (RGB_WAVELENGTHS_M * np.asarray(t)[..., None]))

    ratio = planck(temperature_of_bv(np.asarray(bv, np.float64))) / planck(temperature_of_bv(SUN_BV))
    return ratio / ratio[..., 1:2]


def relative_irradiance(magnitude: np.ndarray) -> np.ndarray:
    """Irradiance of a star of this V magnitude as a fraction of the 1-AU sun's."""
    return 10.0 ** (-0.4 * (np.asarray(magnitude) - SUN_V))


def pixel_solid_angle(camera: CameraSpec, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Solid angle (sr) of the pixels centred at (u, v), from the camera's own rays (any lens)."""

    def direction(du: float, dv: float) -> np.ndarray:
        r = camera.rays(u + du, v + dv)
        return r / np.linalg.norm(r, axis=-1, keepdims=True)

    across = direction(0.5, 0.0) - direction(-0.5, 0.0)
    down = direction(0.0, 0.5) - direction(0.0, -0.5)
    return np.linalg.norm(np.cross(across, down), axis=-1)


def project_stars(camera: CameraSpec, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(pixel positions N x 2, Hp magnitudes, B-V) of the catalogue stars in front of the camera and
    within half a pixel of the image, for the celestial attitude `frame` (ICRS -> camera)."""
    xyz, hp, bv = hipparcos()
    w, h = camera.width, camera.height
    corners = camera.rays(np.array([-1.0, w, -1.0, w]), np.array([-1.0, -1.0, h, h]))
    cos_edge = np.min(corners[:, 2] / np.linalg.norm(corners, axis=1))  # the widest corner, off the axis
    near = np.flatnonzero(xyz @ frame[2] > max(cos_edge - 0.05, 1e-3))  # stars about the field of view
    d = xyz[near] @ frame.T
    near = near[_within(project(camera.K_mat, d), w, h, 0.5 * w, 0.5 * h)]  # where lens models hold
    uv = camera.project(xyz[near] @ frame.T)
    inside = _within(uv, w, h, 1.0, 1.0)
    return uv[inside], hp[near][inside], bv[near][inside]


def _within(uv: np.ndarray, w: int, h: int, margin_x: float, margin_y: float) -> np.ndarray:
    return (
        (uv[:, 0] > -margin_x)
        & (uv[:, 0] < w - 1 + margin_x)
        & (uv[:, 1] > -margin_y)
        & (uv[:, 1] < h - 1 + margin_y)
    )


def star_image(camera: CameraSpec, frame: np.ndarray, boost_ev: float = 0.0) -> np.ndarray:
    """H x W x 3 float32 linear image of the catalogue stars at exposure camera.exposure_ev (+ boost)."""
    h, w = camera.height, camera.width
    uv, hp, bv = project_stars(camera, frame)
    gain = 2.0 ** (boost_ev - camera.exposure_ev)
    flux = np.pi * relative_irradiance(hp) / pixel_solid_angle(camera, uv[:, 0], uv[:, 1]) * gain
    value = flux[:, None] * tint(bv)
    x0, y0 = np.floor(uv[:, 0]).astype(np.int64), np.floor(uv[:, 1]).astype(np.int64)
    fx, fy = uv[:, 0] - x0, uv[:, 1] - y0
    pixels, shares = [], []
    for dy, wy in ((0, 1 - fy), (1, fy)):
        for dx, wx in ((0, 1 - fx), (1, fx)):
            x, y = x0 + dx, y0 + dy
            ok = (x >= 0) & (x < w) & (y >= 0) & (y < h)  # the share that falls outside is lost
            pixels.append(y[ok] * w + x[ok])
            shares.append(value[ok] * (wx * wy)[ok, None])
    # summed per pixel in float64, in the order the four corners and the stars come (np.add.at's)
    touched, which = np.unique(np.concatenate(pixels), return_inverse=True)
    shares = np.concatenate(shares)
    img = np.zeros((h * w, 3), np.float32)
    for c in range(3):
        img[touched, c] = np.bincount(which, shares[:, c], minlength=len(touched))
    return img.reshape(h, w, 3)
