"""The camera's settings: intrinsics, lens, exposure, optics, glare, sensor, output.

`CameraSettings` and its section dataclasses are the one home of every key, its default and its unit
(the default geometry comes from scgen.io.camera_presets); the config's built-in `camera` section
(`DEFAULT_CAMERA`) is their table. One table of presets (`CAMERA_PRESETS`, in scgen.io.camera_presets,
where posenet reads their intrinsics): each entry overrides the `default` camera. A config's table is
checked once at load (`check_camera`) and travels typed with each image (ImagingSpec.camera) to the
camera stage. Ranges are [min, max] drawn uniformly per image (the gain log-uniformly).
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass, field
from typing import Any

from scgen.errors import ScgenError
from scgen.io.camera_presets import DEFAULT_INTRINSICS, preset_entry
from scgen.scenes.config.checks import check_choice, check_positive, check_prob, check_range, is_number

Range = tuple[float, float]  # [min, max], drawn uniformly per image


@dataclass(frozen=True)
class ExposureSettings:
    """How each image's exposure is chosen (scgen.render.camera.exposure)."""

    mode: str = "range"  # fixed | range | auto
    ev_range: Range = (-0.5, 0.5)  # range: EV added per image
    auto_target: float = 0.18  # auto: mean linear value of the target's visible pixels
    auto_limits_ev: Range = (-6.0, 6.0)  # auto: the EV it may add; the upper end caps highlight protection
    # range and auto: highlight protection, as a camera's auto-exposure does it: the exposure is shortened (EV
    # raised) until at most this share of the frame's pixels clips (docs/config.md says why 3 %)
    max_clipped: float = 0.03


@dataclass(frozen=True)
class OpticsSettings:
    """The lens between the scene and the sensor (scgen.render.camera.optics)."""

    psf: str = "gaussian"  # gaussian | defocus (a uniform disc)
    psf_fwhm_px: Range = (0.7, 1.6)  # FWHM of the PSF (a disc's diameter), px
    motion_blur_prob: float = 0.3
    motion_blur_px: Range = (1.0, 4.0)  # line length, px; direction uniform
    vignetting: Range = (0.0, 0.25)  # share of light lost at the farthest image corner
    chromatic_px: Range = (0.0, 0.4)  # lateral colour: red/blue shift at the farthest corner, px


@dataclass(frozen=True)
class GlareSettings:
    """Over-exposure: bloom, column blooming and the sun's flare (scgen.render.camera.glare)."""

    blooming: bool = False  # true: charge above the full well spills along columns (CCD, no anti-blooming)
    bloom: float = 0.02  # share of light above saturation scattered into the wide PSF
    bloom_radius_px: float = 40.0  # half-width of the wide PSF, px
    spikes: int = 6  # diffraction spikes of the wide PSF (0: none)
    flare: bool = True  # ghosts and veiling glare from the sun in or near the field of view
    flare_ghosts: tuple[int, int] = (3, 7)  # ghosts per flare
    ghost_share: Range = (1e-5, 3e-4)  # light in each ghost, as a share of the sun's light on the sensor
    veiling_glare: float = 0.005  # share of the sun's light on the sensor scattered over the image


@dataclass(frozen=True)
class SensorSettings:
    """Photo-electrons to digital values (scgen.render.camera.sensor)."""

    enabled: bool = True
    full_well_e: float = 10500.0  # e-
    full_well_value: float = 1.0  # linear image value that fills the well at gain 1
    gain: Range = (1.0, 16.0)  # analog gain per image (log-uniform): the noise level
    read_noise_e: float = 2.5  # e- rms
    dark_current_e_s: float = 25.0  # e-/s per pixel
    exposure_time_s: float = 0.01  # s
    prnu: float = 0.01  # photo-response non-uniformity, rms share; fixed per dataset
    hot_pixel_frac: float = 1e-4  # share of pixels, fixed per dataset
    hot_pixel_e_s: float = 2e4  # dark current of a hot pixel, e-/s
    dead_pixel_frac: float = 5e-5  # share of pixels, fixed per dataset
    adc_bits: int = 12


@dataclass(frozen=True)
class OutputSettings:
    """The file's pixels (scgen.render.camera.output)."""

    mono: bool = False  # one-channel images (luminance), as SPEED/SPEED+
    bits: int = 8  # 8 or 16 (PNG only)
    curve: str = "srgb"  # srgb | linear
    jpeg_quality: tuple[int, int] = (85, 95)  # drawn per image, for JPEG files (--rgb-format auto's or jpg)


SECTIONS = {"exposure": ExposureSettings, "optics": OpticsSettings, "glare": GlareSettings,
            "sensor": SensorSettings, "output": OutputSettings}  # fmt: skip


@dataclass(frozen=True)
class CameraSettings:
    """The camera table, typed: what travels with each image (ImagingSpec.camera) to the camera stage.

    The config's `camera` section is its `table()`; `from_table` types a resolved, checked one.
    """

    preset: str = "default"
    width: int = DEFAULT_INTRINSICS["width"]  # px
    height: int = DEFAULT_INTRINSICS["height"]  # px
    fx: float = DEFAULT_INTRINSICS["fx"]  # px
    fy: float = DEFAULT_INTRINSICS["fy"]  # px
    cx: float | None = DEFAULT_INTRINSICS["cx"]  # px; None: (width - 1) / 2, the image centre
    cy: float | None = DEFAULT_INTRINSICS["cy"]  # px
    dist: tuple[float, ...] = DEFAULT_INTRINSICS["dist"]  # OpenCV k1, k2, p1, p2, k3 (normalised coordinates)
    exposure_ev: float = 0.0  # base exposure (EV); +1 EV halves every image value
    exposure: ExposureSettings = field(default_factory=ExposureSettings)
    optics: OpticsSettings = field(default_factory=OpticsSettings)
    glare: GlareSettings = field(default_factory=GlareSettings)
    sensor: SensorSettings = field(default_factory=SensorSettings)
    output: OutputSettings = field(default_factory=OutputSettings)

    @staticmethod
    def from_table(table: dict[str, Any]) -> CameraSettings:
        """From a camera table (check_camera's job is done: this only types it; lists become tuples)."""

        def typed(key: str, value: Any) -> Any:
            return (
                SECTIONS[key](**{k: _tupled(v) for k, v in value.items()})
                if key in SECTIONS
                else _tupled(value)
            )

        return CameraSettings(**{key: typed(key, value) for key, value in table.items()})

    def table(self) -> dict[str, Any]:
        """The camera table (plain dicts and lists), as the config holds it and config.json shows it."""
        return _listed(asdict(self))


def _tupled(value: Any) -> Any:
    return tuple(value) if isinstance(value, list) else value


def _listed(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _listed(v) for k, v in value.items()}
    return list(value) if isinstance(value, tuple) else value


DEFAULT_CAMERA: dict[str, Any] = CameraSettings().table()

PX_RANGES = (("optics", "psf_fwhm_px"), ("optics", "motion_blur_px"), ("optics", "chromatic_px"))


def camera_preset(name: str) -> dict[str, Any]:
    """The full camera table of a preset (a deep copy of the default with the preset's entry over it)."""
    entry = preset_entry(name)
    table = copy.deepcopy(DEFAULT_CAMERA)
    for key, value in entry.items():
        if isinstance(value, dict):
            table[key].update(copy.deepcopy(value))
        else:
            table[key] = copy.deepcopy(value)
    table["preset"] = name
    return table


def preset_settings(name: str) -> CameraSettings:
    """A preset's typed settings."""
    return CameraSettings.from_table(camera_preset(name))


def scale_pixel_sizes(camera: dict[str, Any], s: float) -> None:
    """Scale the optics' pixel-sized ranges with the image (a resolution change keeps the optics)."""
    for section, key in PX_RANGES:
        camera[section][key] = [x * s for x in camera[section][key]]


def check_camera(cam: dict[str, Any]) -> None:
    """Every range and choice of the camera table (intrinsics are checked by config.resolve)."""
    if len(cam["dist"]) != 5 or not all(map(is_number, cam["dist"])):
        raise ScgenError(f"camera.dist must be 5 numbers (k1, k2, p1, p2, k3), got {cam['dist']!r}")
    check_choice("camera.exposure.mode", cam["exposure"]["mode"], ("fixed", "range", "auto"))
    check_choice("camera.optics.psf", cam["optics"]["psf"], ("gaussian", "defocus"))
    check_choice("camera.output.curve", cam["output"]["curve"], ("srgb", "linear"))
    check_choice("camera.output.bits", cam["output"]["bits"], (8, 16))
    check_range("camera.exposure.ev_range", cam["exposure"]["ev_range"], -30.0)
    check_range("camera.exposure.auto_limits_ev", cam["exposure"]["auto_limits_ev"], -30.0)
    check_positive("camera.exposure.auto_target", cam["exposure"]["auto_target"])
    check_prob("camera.exposure.max_clipped", cam["exposure"]["max_clipped"])
    for key in ("psf_fwhm_px", "motion_blur_px", "chromatic_px"):
        check_range(f"camera.optics.{key}", cam["optics"][key], 0.0)
    check_range("camera.optics.vignetting", cam["optics"]["vignetting"], 0.0)
    if cam["optics"]["vignetting"][1] >= 1.0:
        raise ScgenError(f"camera.optics.vignetting must stay below 1, got {cam['optics']['vignetting']}")
    check_prob("camera.optics.motion_blur_prob", cam["optics"]["motion_blur_prob"])
    glare = cam["glare"]
    check_prob("camera.glare.bloom", glare["bloom"])
    check_positive("camera.glare.bloom_radius_px", glare["bloom_radius_px"])
    if not isinstance(glare["spikes"], int) or glare["spikes"] < 0:
        raise ScgenError(f"camera.glare.spikes must be a whole number >= 0, got {glare['spikes']!r}")
    check_range("camera.glare.flare_ghosts", glare["flare_ghosts"], 0)
    check_range("camera.glare.ghost_share", glare["ghost_share"], 0.0)
    check_prob("camera.glare.veiling_glare", glare["veiling_glare"])
    sensor = cam["sensor"]
    for key in ("full_well_e", "full_well_value", "exposure_time_s"):
        check_positive(f"camera.sensor.{key}", sensor[key])
    for key in ("read_noise_e", "dark_current_e_s", "prnu", "hot_pixel_e_s"):
        if sensor[key] < 0:
            raise ScgenError(f"camera.sensor.{key} must be >= 0, got {sensor[key]}")
    check_range("camera.sensor.gain", sensor["gain"], 1e-6)
    for key in ("hot_pixel_frac", "dead_pixel_frac"):
        check_prob(f"camera.sensor.{key}", sensor[key])
    if sensor["adc_bits"] not in range(8, 17):
        raise ScgenError(f"camera.sensor.adc_bits must be 8..16, got {sensor['adc_bits']!r}")
    q = cam["output"]["jpeg_quality"]
    check_range("camera.output.jpeg_quality", q, 1)
    if q[1] > 100:
        raise ScgenError(f"camera.output.jpeg_quality must lie in [1, 100], got {q}")
