"""Illumination levels: physical sun units, and clearly different rendered target brightness."""

from __future__ import annotations

import numpy as np
import pytest

from scgen.generator import Generator
from scgen.render.lighting import body_albedo_light, mean_luminance, sun_render_irradiance
from scgen.scenes import load_config
from scgen.scenes.model import load_target

LEVELS = ("weak", "normal", "strong")


def level_config(level: str, resolution=(160, 120)) -> dict:
    return load_config(overrides={"illumination": {"probs": {level: 1.0}}}, resolution=resolution)


def test_sun_is_in_physical_units_and_the_camera_model_maps_one_au_to_one():
    cfg = load_config()
    for level in LEVELS:
        generator = Generator(load_target(), level_config(level), 0)
        spec = generator.scene(0)
        # the sampler's own product of the same two floats
        assert spec.sun.irradiance == 1361.0 * cfg["illumination"]["multipliers"][level]
    generator = Generator(load_target(), level_config("normal"), 0)
    spec = generator.scene(0)
    assert sun_render_irradiance(spec) == pytest.approx(np.pi)  # white Lambert plate -> image value 1.0


def test_the_earth_and_the_moon_are_a_second_light_only_where_they_are_in_the_sky():
    """The body's reflected light a * E * sin^2(rho) * f: the Moon's at its albedo (0.12), from where
    it is; none over a clean sky."""
    for kind in ("earth", "complex", "clean"):
        cfg = load_config(overrides={"background": {"probs": {kind: 1.0}}})
        generator = Generator(load_target(), cfg, 1)
        specs = [generator.scene(i) for i in range(5)]
        lights = [body_albedo_light(s) for s in specs]
        if kind == "clean":
            assert all(light is None for light in lights)
            continue
        assert all(light is not None and light[1] > 0 for light in lights)
        if kind == "complex":
            for spec, (direction, irradiance) in zip(specs, lights, strict=True):
                params = spec.background.params
                lit = 0.5 * (1 - np.dot(params["centre_dir"], spec.sun.direction))
                e = 0.12 * spec.sun.irradiance * np.sin(np.deg2rad(params["angular_radius_deg"])) ** 2 * lit
                assert np.array_equal(direction, params["centre_dir"])  # the params' vector as it is
                # the same float64 factors in another order: a few roundings a side, ~1e-15, where a missing
                # factor (pi, the lit half, the albedo) is O(1)
                assert irradiance == pytest.approx(
                    np.pi * e / 1361.0 * 2.0**-spec.camera.exposure_ev, rel=1e-14
                )


def test_levels_give_disjoint_interquartile_ranges_of_target_luminance():
    """Same 12 scenes (per-factor streams keep everything but the level) rendered at each level."""
    model = load_target()
    quartiles = []
    for level in LEVELS:
        with Generator(model, level_config(level), 4, backend="mitsuba", quality="draft") as generator:
            samples = [generator.sample(i) for i in range(12)]
        values = [mean_luminance(s.buffers.rgb, s.annotation.mask_visib) for s in samples]
        quartiles.append(np.percentile(values, [25, 75]))
    assert quartiles[0][1] < quartiles[1][0] and quartiles[1][1] < quartiles[2][0], quartiles
