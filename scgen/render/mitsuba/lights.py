"""The Mitsuba backend's directional lights: the sun and the Earth's reflected light of a sample, written
into the lights of a scene kept for the run, and the steady bounding sphere they are given.

A light's direction and irradiance are written in place (memory) into memory each light owns
from its scene's start: setting them through mi.traverse launched about 80 kernels a sample (every entry
of a new transform made opaque), and a frozen render reads them from that memory either way.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from scgen.render.conventions import CLIP_END_M, EARTHSHINE_COLOUR
from scgen.render.lighting import body_albedo_light, sun_render_irradiance
from scgen.render.mitsuba.memory import channels, check_held, overwrite, own_scalars
from scgen.scenes.spec import SceneSpec

ROTATION = [(r, c) for r in range(3) for c in range(3)]  # the entries of a light's frame that vary
LIGHT_BOUNDS_HALF_M = CLIP_END_M  # no geometry renders beyond the far clip: the cube holds every scene
LIGHT_KEYS = ("to_world", "irradiance.value")  # what a directional light takes from each sample


def sample_lights(spec: SceneSpec) -> dict[str, dict]:
    """The sample's directional lights as Mitsuba dicts: the sun, and the Earth's reflected light where
    it has one."""
    lights = {
        "sun": {
            "type": "directional",
            "direction": [-float(x) for x in spec.sun.direction],
            "irradiance": {"type": "rgb", "value": sun_render_irradiance(spec)},
        }
    }
    albedo = body_albedo_light(spec)
    if albedo is not None:
        direction, irradiance = albedo
        lights["earthshine"] = {
            "type": "directional",
            "direction": [-float(x) for x in direction],
            "irradiance": {"type": "rgb", "value": [c * irradiance for c in EARTHSHINE_COLOUR]},
        }
    return lights


def directional_frame(direction: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """The to_world matrix (and its inverse transpose) Mitsuba's directional emitter builds for
    `direction`, to the bit: computed by the same C++ functions (normalise in float32, coordinate_system,
    look_at). Python's drjit.normalize rounds differently, so the normalised direction is taken from a
    first look_at, whose third column is exactly that."""
    look_at, origin = mi.ScalarAffineTransform4f.look_at, mi.ScalarPoint3f(0.0)
    helper = np.zeros(3)
    helper[int(np.argmin(np.abs(direction)))] = 1.0  # any up vector not along the direction
    first = look_at(origin=origin, target=mi.ScalarPoint3f(*direction), up=mi.ScalarVector3f(*helper))
    unit = mi.ScalarVector3f(*np.asarray(first.matrix)[:3, 2])
    up, _ = mi.scalar_rgb.coordinate_system(unit)
    frame = look_at(origin=origin, target=mi.ScalarPoint3f(unit), up=up)
    return np.asarray(frame.matrix, np.float32), np.asarray(frame.inverse_transpose, np.float32)


def irradiance_rgb(light: dict) -> np.ndarray:
    """A light dict's irradiance as the three float32 channels Mitsuba stores (a number is grey)."""
    return np.broadcast_to(np.asarray(light["irradiance"]["value"], np.float32), (3,))


class SceneLights:
    """The directional lights of a kept scene, set to each sample's in place, with the bounding sphere they
    are given (steady_light_bounds)."""

    def __init__(self, scene: mi.Scene, names: list[str]) -> None:
        self._params = mi.traverse(scene)
        self._params.keep([f"{name}.{key}" for name in names for key in LIGHT_KEYS])
        self._arrays: dict[str, list[mi.Float]] = {}  # per light: the Floats overwritten (see _varying)
        if dr.is_jit_v(mi.Float):
            for name in names:
                self._own(name)
            self._params.update()
            self._arrays = {name: _varying(self._params, name) for name in names}
            live = mi.traverse(scene)
            check_held([a for name in names for a in self._arrays[name]],
                       [a for name in names for a in _varying(live, name)], "lights")  # fmt: skip
        steady_light_bounds(scene)  # after the update above, as a sample's rebuild leaves it

    def _own(self, name: str) -> None:
        """Give light `name`'s varying values memory of their own (see memory.own_scalars)."""
        frame, colour = self._params[f"{name}.to_world"], self._params[f"{name}.irradiance.value"]
        parts = []
        for part in (frame.matrix, frame.inverse_transpose):
            values = own_scalars(float(part[r][c][0]) for r, c in ROTATION)
            for (r, c), value in zip(ROTATION, values, strict=True):
                part[r][c] = value
            parts.append(part)
        self._params[f"{name}.to_world"] = mi.AffineTransform4f(*parts)
        self._params[f"{name}.irradiance.value"] = mi.Color3f(*own_scalars(c[0] for c in channels(colour)))

    def set(self, lights: dict[str, dict]) -> None:
        """Give the lights these values (sample_lights' dicts, one per light of the scene). The caller has
        waited for the kernels reading them (drjit.sync_thread)."""
        if not dr.is_jit_v(mi.Float):  # scalar_rgb: its values are plain numbers, set the usual way
            for name, light in lights.items():
                new = mi.traverse(mi.load_dict(light))
                for key in LIGHT_KEYS:
                    self._params[f"{name}.{key}"] = new[key]
            self._params.update()
        else:
            for name, light in lights.items():
                matrix, inverse_transpose = directional_frame(light["direction"])
                values = [m[r, c] for m in (matrix, inverse_transpose) for r, c in ROTATION]
                overwrite(self._arrays[name], [*values, *irradiance_rgb(light)])


def _varying(params: mi.SceneParameters, name: str) -> list[mi.Float]:
    """What a sample changes of light `name`: its frame's rotation (matrix, inverse transpose), irradiance."""
    frame, colour = params[f"{name}.to_world"], params[f"{name}.irradiance.value"]
    rotation = [part[r][c] for part in (frame.matrix, frame.inverse_transpose) for r, c in ROTATION]
    return rotation + channels(colour)


def steady_light_bounds(scene: mi.Scene) -> None:
    """Give the directional lights one bounding sphere about the camera for every sample: that of a cube
    of half side LIGHT_BOUNDS_HALF_M. They keep it as constants of the render kernel, so the scene's own
    sphere compiled a new kernel for every sample (and a frozen render would replay a stale one). The
    sphere only sets how far a shadow ray towards the light is cast (twice the larger of its radius and
    the point's distance from its centre): far enough past any geometry, a longer ray finds the same
    occluders, so one sphere holding every scene serves all of them, with no recording per scene size."""
    cube = {"type": "cube", "to_world": mi.ScalarTransform4f().scale([LIGHT_BOUNDS_HALF_M] * 3)}
    bounds = mi.load_dict({"type": "scene", "cube": cube})
    for emitter in scene.emitters():
        emitter.set_scene(bounds)
