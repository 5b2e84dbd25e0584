"""The sky's attitude per sample: the stars and the Earth turned consistently with the sampled sun.

The sun direction (camera frame) is sampled first, for the target's lighting. The celestial frame
(ICRS) is then drawn so the sun sits on the ecliptic at a random longitude (a random date), with a
random roll about the sun direction; the Earth spins about the celestial pole by a random sidereal
angle (a random time of day). So the stars, the Earth's axis and its day side agree with each other.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from scgen.scenes.geometry import orthonormal_basis

OBLIQUITY_RAD = np.deg2rad(23.439)  # of the ecliptic to the celestial equator
SKY_KINDS = ("clean", "complex", "earth", "cluttered")  # the kinds with a sky (not the user's images)
SKY_COLUMNS = ("earth_lat_deg", "earth_lon_deg", "sky_ra_deg", "sky_dec_deg")  # metadata.csv
BODY_OF_KIND = {"earth": "earth", "complex": "moon"}  # the sunlit body a background kind shows
BODIES = tuple(BODY_OF_KIND.values())


def _rz(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def sun_icrs(ecliptic_longitude: float) -> np.ndarray:
    """Unit ICRS direction of the sun at this ecliptic longitude (rad)."""
    lam = ecliptic_longitude
    return np.array([np.cos(lam), np.sin(lam) * np.cos(OBLIQUITY_RAD), np.sin(lam) * np.sin(OBLIQUITY_RAD)])


def celestial_frame(sun_cam: np.ndarray, ecliptic_longitude: float, roll: float) -> np.ndarray:
    """Rotation ICRS -> camera that takes the sun's ICRS direction onto `sun_cam`, rolled about it."""
    a = sun_icrs(ecliptic_longitude)
    s = np.asarray(sun_cam, np.float64)
    ua, wa = orthonormal_basis(a)
    us, ws = orthonormal_basis(s)
    us, ws = np.cos(roll) * us + np.sin(roll) * ws, -np.sin(roll) * us + np.cos(roll) * ws
    return np.stack([s, us, ws], axis=1) @ np.stack([a, ua, wa], axis=0)


def draw_sky(rng: np.random.Generator, sun_cam: np.ndarray) -> dict[str, Any]:
    """The sky's background params: the ICRS -> camera rotation (row-major) and the Earth's spin (deg)."""
    lam, roll, spin = rng.uniform(0.0, 2 * np.pi, 3)
    frame = celestial_frame(sun_cam, lam, roll)
    return {"sky_frame": [float(x) for x in frame.ravel()], "earth_spin_deg": float(np.rad2deg(spin))}


def sky_params(kind: str, cfg: dict[str, Any], rng: np.random.Generator, sun_cam: np.ndarray) -> dict:
    """What the real sky adds to a background's params (config `background`): with Hipparcos stars or a
    Blue Marble Earth in the frame, the drawn sky and the sources; nothing for procedural skies."""
    if not shows_sky(kind, cfg):
        return {}
    return sky_background(kind, cfg, draw_sky(rng, sun_cam))


def shows_sky(kind: str, cfg: dict[str, Any]) -> bool:
    """Whether a background of this kind shows the real sky: Hipparcos stars or a Blue Marble Earth."""
    return (kind in SKY_KINDS and cfg["stars"] == "hipparcos") or (
        kind == "earth" and cfg["earth_map"] == "bluemarble"
    )


def sky_background(kind: str, cfg: dict[str, Any], sky: dict[str, Any]) -> dict:
    """A background's sky params from its sky (`draw_sky`'s keys: sky_frame, earth_spin_deg) and the
    config's sources; {} where the kind shows no real sky."""
    if not shows_sky(kind, cfg):
        return {}
    stars = kind in SKY_KINDS and cfg["stars"] == "hipparcos"
    earth = kind == "earth" and cfg["earth_map"] == "bluemarble"
    out = dict(sky)
    if stars:
        out |= {"stars": "hipparcos", "stars_boost_ev": float(cfg["stars_boost_ev"])}
    if earth:
        out["earth_map"] = "bluemarble"
    return out


def sky_frame(params: dict[str, Any]) -> np.ndarray:
    """Rotation ICRS -> camera of a sample's background params."""
    return np.asarray(params["sky_frame"], np.float64).reshape(3, 3)


def earth_frame(params: dict[str, Any]) -> np.ndarray:
    """Rotation camera -> Earth-fixed (z: north pole, x: Greenwich meridian) of an Earth's params."""
    return _rz(-np.deg2rad(params["earth_spin_deg"])) @ sky_frame(params).T


def lat_lon_deg(v: np.ndarray) -> tuple[float, float]:
    """Latitude and longitude (deg) of a direction in a frame whose z is the pole."""
    v = np.asarray(v, np.float64) / np.linalg.norm(v)
    return float(np.rad2deg(np.arcsin(np.clip(v[2], -1, 1)))), float(np.rad2deg(np.arctan2(v[1], v[0])))


def body_centre(params: dict[str, Any]) -> np.ndarray:
    """Camera-frame centre of the background's sunlit body, in its own radii: a unit sphere at this
    distance along `centre_dir` subtends `angular_radius_deg`."""
    rho = np.deg2rad(params["angular_radius_deg"])
    return np.asarray(params["centre_dir"], np.float64) / np.sin(rho)


def background_holds(kind: str, params: dict[str, Any]) -> str:
    """What a background shows, for metadata.csv: 'earth limb', 'moon disc', 'stars', 'stars, props' or
    'user image'."""
    if kind in BODY_OF_KIND:
        return f"{BODY_OF_KIND[kind]} {'limb' if params['limb'] else 'disc'}"
    return {"clean": "stars", "cluttered": "stars, props"}.get(kind, "user image")


def sky_labels(params: dict[str, Any]) -> dict[str, float | str]:
    """The metadata of a sample's sky: where the camera looks on the celestial sphere (RA, Dec of the
    optical axis) and, with a Blue Marble Earth, the sub-camera point (latitude, longitude); '' if none."""
    out: dict[str, float | str] = dict.fromkeys(SKY_COLUMNS, "")
    if "sky_frame" in params:
        dec, ra = lat_lon_deg(sky_frame(params).T @ np.array([0.0, 0.0, 1.0]))
        out["sky_ra_deg"], out["sky_dec_deg"] = ra % 360.0, dec
    if params.get("earth_map") == "bluemarble":
        out["earth_lat_deg"], out["earth_lon_deg"] = lat_lon_deg(
            earth_frame(params) @ -np.asarray(params["centre_dir"], np.float64)
        )
    return out
