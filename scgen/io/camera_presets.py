"""The camera presets (`--camera NAME`, a config's `camera.preset`) and the geometry of the default camera.

Each preset overrides the default camera key by key (scgen.scenes.config.camera builds, types and checks
the full table). They sit on scgen's bottom floor so that a pose predictor reads a preset's camera,
`preset_intrinsics`, through scgen.io (`posenet predict --camera speedplus`).
"""

from __future__ import annotations

from typing import Any

from scgen.errors import ScgenError

# the default camera's geometry (scgen.scenes.config.camera.CameraSettings' defaults): a 640x480 image, a
# 56 deg horizontal field of view, the principal point at the image centre (None: (size - 1) / 2), no
# distortion
DEFAULT_INTRINSICS: dict[str, Any] = {
    "width": 640,  # px
    "height": 480,  # px
    "fx": 600.0,  # px
    "fy": 600.0,  # px
    "cx": None,  # px; None: (width - 1) / 2, the image centre under the pixel-centre convention
    "cy": None,  # px
    "dist": (0.0, 0.0, 0.0, 0.0, 0.0),  # OpenCV k1, k2, p1, p2, k3 (normalised coordinates)
}

CAMERA_PRESETS: dict[str, dict[str, Any]] = {
    "ideal": {  # the images before the camera stage: a perfect pinhole camera at a fixed exposure
        "exposure": {"mode": "fixed"},
        "optics": {
            "psf_fwhm_px": [0.0, 0.0],
            "motion_blur_prob": 0.0,
            "vignetting": [0.0, 0.0],
            "chromatic_px": [0.0, 0.0],
        },  # fmt: skip
        "glare": {"blooming": False, "bloom": 0.0, "flare": False},
        "sensor": {"enabled": False},
        "output": {"jpeg_quality": [95, 95]},
    },
    "default": {},  # a machine-vision CMOS camera (anti-blooming drains) at 640x480, 56 deg field of view
    "ccd": {  # the default camera on a CCD without anti-blooming drains: full wells spill along columns
        "glare": {"blooming": True},
    },
    "speedplus": {  # SPEED+'s camera (1920x1200, calibrated K and distortion, monochrome), IMX174-like sensor
        "width": 1920,
        "height": 1200,
        "fx": 2988.5795,
        "fy": 2988.3401,
        "cx": 960.0,
        "cy": 600.0,
        "dist": [-0.22383, 0.51410, -0.00066, -0.00021, -0.13124],
        "optics": {"psf_fwhm_px": [1.8, 2.8], "motion_blur_px": [1.0, 6.0], "chromatic_px": [0.0, 0.0]},
        "sensor": {"full_well_e": 32000.0, "read_noise_e": 7.0, "gain": [1.0, 8.0]},
        "output": {"mono": True, "jpeg_quality": [80, 95]},
    },
}


def preset_entry(name: str) -> dict[str, Any]:
    """A preset's overrides of the default camera; an unknown name is one ScgenError naming the choices."""
    if name not in CAMERA_PRESETS:
        raise ScgenError(f"unknown camera preset '{name}' (choose from {', '.join(CAMERA_PRESETS)})")
    return CAMERA_PRESETS[name]


def preset_intrinsics(name: str) -> tuple[list[list[float]], list[float], tuple[int, int]]:
    """(K, OpenCV distortion, (width, height)) of a preset's camera: what a pose predictor needs to read
    images taken by it."""
    cam = {**DEFAULT_INTRINSICS, **{k: v for k, v in preset_entry(name).items() if k in DEFAULT_INTRINSICS}}
    w, h = int(cam["width"]), int(cam["height"])
    cx = (w - 1) / 2 if cam["cx"] is None else float(cam["cx"])
    cy = (h - 1) / 2 if cam["cy"] is None else float(cam["cy"])
    K = [[float(cam["fx"]), 0.0, cx], [0.0, float(cam["fy"]), cy], [0.0, 0.0, 1.0]]
    return K, [float(k) for k in cam["dist"]], (w, h)
