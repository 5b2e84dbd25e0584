"""Illumination levels: physical sun units, and clearly different rendered target brightness."""

from __future__ import annotations

import numpy as np
import pytest

from scgen.generator import Generator
from scgen.render.lighting import earth_albedo_light, mean_luminance, sun_render_irradiance
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
        assert spec.sun.irradiance == pytest.approx(1361.0 * cfg["illumination"]["multipliers"][level])
    generator = Generator(load_target(), level_config("normal"), 0)
    spec = generator.scene(0)
    assert sun_render_irradiance(spec) == pytest.approx(np.pi)  # white Lambert plate -> image value 1.0


def test_earth_albedo_is_a_second_light_only_with_the_earth():
    for kind in ("earth", "clean"):
        cfg = load_config(overrides={"background": {"probs": {kind: 1.0}}})
        generator = Generator(load_target(), cfg, 1)
        specs = [generator.scene(i) for i in range(5)]
        lights = [earth_albedo_light(s) for s in specs]
        if kind == "earth":
            assert all(light is not None and light[1] > 0 for light in lights)
        else:
            assert all(light is None for light in lights)


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
