"""Blender (bpy + Cycles) backend, the default renderer: exact pixel-centre labels, fast, flat memory.

Per sample: update the persistent scenes in place (scene), render the anti-aliased beauty
image (RGB + depth + object index from the centred first sample), then a one-sample aux render
(normals, sun visibility, target-alone depth), and turn the passes into Buffers (pure numpy). Both
renders trace only the regions the objects may cover (scgen.render.region): outside them every pass is
what a pixel that meets nothing gives, so labels and the undenoised image are the full frame's exactly.
bpy is imported only when a backend is made, so scgen works without it for other backends.
"""

from __future__ import annotations

import shutil
import tempfile
import weakref
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from scgen.io.bop import TARGET_OBJ_ID
from scgen.io.buffers import BACKGROUND_ID, TARGET_ID, Buffers
from scgen.render.blender.env import import_bpy, select_device
from scgen.render.blender.scene import ALONE, BEAUTY, PROBE, BlenderScene
from scgen.render.blender.settings import FILTER_REACH_PX, preset
from scgen.render.camera import record_image, render_camera
from scgen.render.objects import model_hulls, objects_alone_depth, with_target
from scgen.render.region import Region, full_frame, holding, region_render, scene_regions, target_region
from scgen.render.sky.backgrounds import background_image
from scgen.scenes.geometry import project
from scgen.scenes.model import TargetModel
from scgen.scenes.spec import SceneSpec

if TYPE_CHECKING:
    from scgen.render.mitsuba.backend import MitsubaBackend

GRAZING = 1e-4  # |n.s| below this: the surface is edge-on to the sun, its visibility is not measured
# Empty pixels traced around each object's box for the denoiser's view of its surroundings: none, since
# OIDN gives the same image over the objects without them (bench_blender.py --margin-frames 12: 0 and 16 px
# 39.02 and 39.04 dB over the objects against a 512-spp reference, 18 and 25 % of the frame traced)
DENOISE_MARGIN_PX = 0


class BlenderBackend:
    """Renders SceneSpecs with Cycles; one live instance per process (bpy is a process-wide singleton)."""

    name = "blender"

    def __init__(
        self,
        model: TargetModel,
        quality: str = "default",
        device: str = "auto",
        threads: int | None = None,
        region: bool | None = None,
        models: Mapping[int, TargetModel] | None = None,
    ) -> None:
        """`device`: auto (a GPU when Cycles finds one), cpu or gpu; `threads`: CPU threads (None: all);
        `region`: trace only the pixels the objects may cover (covered_regions), else the whole frame
        (None: as region_render() says); `models`: every object's model by obj_id, for SceneSpec.objects
        (None: the target's alone)."""
        quality_preset = preset(quality)
        self._bpy = import_bpy(threads)
        self._bpy.ops.wm.read_factory_settings(use_empty=True)  # also resets the device preferences
        self.device = select_device(self._bpy, device)
        self._workdir = Path(tempfile.mkdtemp(prefix="scgen-blender-", dir=_ram_dir()))
        # removed on close(), or when the backend is collected or the interpreter exits unclosed
        self._remove_workdir = weakref.finalize(self, shutil.rmtree, self._workdir, True)
        gpu = self.device != "CPU"
        self.models = with_target(model, models)
        self.scene = BlenderScene(self._bpy, model, quality_preset, gpu, threads, self._workdir, self.models)
        self._hulls = model_hulls(self.models)
        self._model, self._rays = model, None
        self.trace_region = region_render() if region is None else region
        self.margin_px = DENOISE_MARGIN_PX  # around each traced box (benchmarks vary it)

    @property
    def cycles_s(self) -> float:
        """Seconds spent inside Cycles' render calls so far (EXR writing included)."""
        return self.scene.cycles_s

    def render(self, spec: SceneSpec) -> Buffers:
        shown = replace(spec, camera=render_camera(spec.camera))
        self.scene.update(shown)
        regions = self.regions(shown)
        beauty = self.scene.render_beauty(regions)
        if shown.camera == spec.camera:  # not `is`: render_camera's cache returns an equal camera of before
            instance, depth = instance_and_depth(beauty)
            hidden = props_may_hide_target(spec, self._hulls[TARGET_OBJ_ID], instance, depth)
            aux = self.scene.render_aux(hidden, self.target_regions(shown, regions))
            buffers = buffers_from_passes(spec, beauty, aux)
            buffers.objects_depth = objects_alone_depth(spec, self.models)
        else:  # a lens Cycles' pinhole image does not sample: labels by exact ray casts along its rays
            buffers = self._ray_caster().render_geometry(spec)
        image = composite(beauty, background_image(shown))
        buffers.rgb, buffers.camera = record_image(spec, image, buffers.instance)
        return buffers

    def regions(self, spec: SceneSpec) -> tuple[Region, ...]:
        """The parts of `spec`'s frame Cycles traces: around the target's hull and the props' meshes."""
        if not self.trace_region:
            return (full_frame(spec.camera.width, spec.camera.height),)
        return scene_regions(spec, self._hulls, FILTER_REACH_PX, self.margin_px)

    def target_regions(self, spec: SceneSpec, regions: tuple[Region, ...]) -> tuple[Region, ...]:
        """The parts of `regions` the aux render traces: the one holding the target, since its passes are
        read on the target's pixels alone (the shadow label's normals and sun visibility, the target-alone
        depth); a prop's or another object's box apart from it is left out."""
        if not self.trace_region:
            return regions
        return holding(regions, target_region(spec, self._hulls, FILTER_REACH_PX, self.margin_px))

    def _ray_caster(self) -> MitsubaBackend:
        """The Mitsuba backend's exact geometric passes, made on first need (cameras with a lens)."""
        if self._rays is None:
            from scgen.render.mitsuba.backend import MitsubaBackend

            self._rays = MitsubaBackend(self._model, models=self.models)  # Dr.Jit's threads: the default
        return self._rays

    def close(self) -> None:
        """Free every Blender datablock (and Cycles' persistent data) and the EXR folder."""
        self._bpy.ops.wm.read_factory_settings(use_empty=True)
        self._remove_workdir()


def _ram_dir() -> str | None:
    """/dev/shm where it exists: the per-frame EXRs never touch the disk."""
    return "/dev/shm" if Path("/dev/shm").is_dir() else None


def instance_and_depth(beauty: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Instance ids and z-depth (0 on the background) from the beauty render's centred first samples."""
    instance = np.rint(beauty[f"{BEAUTY}.Object Index.X"]).astype(np.int32)
    depth = np.where(instance != BACKGROUND_ID, beauty[f"{BEAUTY}.Depth.Z"], 0.0).astype(np.float32)
    return instance, depth


def props_may_hide_target(spec: SceneSpec, hull: np.ndarray, instance: np.ndarray, depth: np.ndarray) -> bool:
    """False only when no prop (nor labelled object beside the target) can hide any target pixel, so the
    target-alone depth needs no render.

    A hidden target pixel lies in the box of the projected hull vertices (model frame `hull`)
    under a prop pixel nearer than the target's farthest point.
    """
    if not spec.props and not spec.objects:
        return False
    x = hull @ spec.target.R_mat.T + spec.target.t_vec
    if x[:, 2].min() <= 0:  # partly behind the camera: the projected box is not a bound
        return True
    uv = project(spec.camera.K_mat, x)
    h, w = instance.shape
    u0, v0 = np.clip(np.floor(uv.min(0)).astype(int), 0, [w, h])
    u1, v1 = np.clip(np.ceil(uv.max(0)).astype(int) + 1, 0, [w, h])
    window = np.s_[v0:v1, u0:u1]
    return bool(((instance[window] > TARGET_ID) & (depth[window] < x[:, 2].max())).any())


def composite(beauty: dict[str, np.ndarray], background: np.ndarray) -> np.ndarray:
    """The linear beauty image over the background (straight alpha from Cycles' film transparency)."""
    rgba = np.stack([beauty[f"{BEAUTY}.Combined.{c}"] for c in "RGBA"], axis=-1)
    alpha = np.clip(rgba[..., 3:], 0.0, 1.0)
    return rgba[..., :3] + (1.0 - alpha) * background


def buffers_from_passes(
    spec: SceneSpec, beauty: dict[str, np.ndarray], aux: dict[str, np.ndarray]
) -> Buffers:
    """The label passes from the EXR channels of the beauty and aux renders (see scene for the
    layers); the image is the camera stage's."""
    instance, depth = instance_and_depth(beauty)
    on_target = instance == TARGET_ID
    if f"{ALONE}.Depth.Z" in aux:
        alone = aux[f"{ALONE}.Depth.Z"]
        target_depth = np.where(alone < 1e9, alone, 0.0).astype(np.float32)  # Cycles' miss depth is 1e10
    else:
        target_depth = np.where(on_target, depth, 0.0).astype(np.float32)

    normal = np.stack([aux[f"{PROBE}.Normal.{c}"] for c in "XYZ"], axis=-1)
    length = np.linalg.norm(normal, axis=-1, keepdims=True)
    unit = normal / np.maximum(length, 1e-12)
    normal = np.where(on_target[..., None] & (length > 0), unit, 0.0).astype(np.float32)
    edge_on = np.abs(normal @ np.asarray(spec.sun.direction, np.float32)) <= GRAZING
    sun_blocked = on_target & (aux[f"{PROBE}.Combined.R"] <= 0.0) & ~edge_on

    return Buffers(
        rgb=np.zeros((*instance.shape, 3), np.uint8),
        depth=depth,
        instance=instance,
        target_depth=target_depth,
        normal=normal,
        sun_blocked=sun_blocked,
    )
