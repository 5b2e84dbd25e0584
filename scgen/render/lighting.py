"""Radiometry shared by every backend: sun and Earth-albedo irradiance under the camera exposure.

Camera model: an image value of 1.0 (before sRGB encoding and clipping) is what a white
Lambertian plate facing a 1-AU sun (1361 W/m^2) gives at exposure EV 0; each +1 EV halves it.
So EV 0 is "expose to the right": the brightest diffuse surface just does not clip. The
illumination levels scale the sun irradiance (config illumination.multipliers), which for the
image is the same as an exposure shift of log2(multiplier) EV; camera.exposure_ev itself is a
fixed, logged setting that no level changes.
A renderer whose Lambertian radiance is albedo * E * cos / pi must be given E * pi * scale.
"""

from __future__ import annotations

import numpy as np

from scgen.render.conventions import LUMA
from scgen.render.sky.earth_surface import disc_albedo
from scgen.scenes.sky import BODY_OF_KIND
from scgen.scenes.spec import SceneSpec

SOLAR_CONSTANT = 1361.0


def exposure_scale(spec: SceneSpec) -> float:
    """Linear image value per (W/m^2 of irradiance on a white Lambertian plate)."""
    return 2.0 ** (-spec.camera.exposure_ev) / SOLAR_CONSTANT


def sun_render_irradiance(spec: SceneSpec) -> float:
    """Irradiance to give a renderer's directional sun so image values follow the camera model."""
    return float(np.pi * spec.sun.irradiance * exposure_scale(spec))


def body_albedo_light(spec: SceneSpec) -> tuple[np.ndarray, float] | None:
    """(direction towards the body, renderer irradiance) of the Earth's or the Moon's reflected light
    (the background's sunlit body), or None.

    A Lambertian sphere of albedo a subtending angular radius rho and lit at phase such that a
    fraction f = (1 - s.c) / 2 of the visible disc is day side gives about a * E * sin^2(rho) * f.
    A Blue Marble Earth's albedo is its imagery's (clouds included) over the lit visible disc; the
    procedural Earth's and the Moon's are the config's.
    """
    if spec.background.kind not in BODY_OF_KIND:
        return None
    params = spec.background.params
    c = np.asarray(params["centre_dir"], np.float64)
    s = np.asarray(spec.sun.direction, np.float64)
    lit = 0.5 * (1.0 - float(c @ s))
    rho = np.deg2rad(params["angular_radius_deg"])
    if params.get("earth_map") == "bluemarble":
        albedo = disc_albedo(params, s, spec.background.seed)
    else:
        albedo = params["albedo"]
    e = albedo * spec.sun.irradiance * np.sin(rho) ** 2 * lit
    if e <= 0:
        return None
    return c, float(np.pi * e * exposure_scale(spec))


def mean_luminance(rgb: np.ndarray, mask: np.ndarray) -> float:
    """Mean linear luminance (Rec. 709 Y of the decoded sRGB pixels) over `mask`; 0 for an empty mask."""
    if not mask.any():
        return 0.0
    x = rgb[mask].astype(np.float64) / 255.0
    lin = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)
    return float((lin @ LUMA).mean())
