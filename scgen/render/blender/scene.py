"""The persistent Blender scenes of one worker: built once, updated in place per SceneSpec.

Two scenes share the camera, the target and the prop objects (linked, not copied):
- `scgen` renders the beauty image (sun, Earth albedo, the materials) with depth and object
  index passes taken from each pixel's centred first sample;
- `scgen_aux` renders one centred sample per pixel with a probe material and a probe sun whose
  shadows only props cast (shadow linking): layer `probe` gives normals and sun visibility,
  layer `alone` (props excluded) the target-alone depth.
The Blender world frame is the OpenCV camera frame, so poses, prop meshes and light directions
from the SceneSpec are used as they are (props are meshed in their own frame and placed by their
pose, so their procedural textures stick to them). Per sample only matrices, prop meshes
(rewritten in place in a pool of objects), light settings and the seed change: nothing is created
or freed, so Cycles' persistent data stays valid and memory stays flat. bpy is passed in, never
imported here, so the layer names can be imported without it.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import OpenEXR

from scgen.io.buffers import TARGET_ID, prop_instance_id
from scgen.render.blender.env import quiet_stdout
from scgen.render.blender.frames import camera_matrix_world, intrinsics_from_K, light_matrix_world
from scgen.render.blender.materials import build_materials, new_material, probe_material, set_finish
from scgen.render.blender.settings import (
    SUN_ANGLE_RAD,
    QualityPreset,
    configure_aux,
    configure_beauty,
    configure_common,
)
from scgen.render.conventions import CLIP_END_M, CLIP_START_M, EARTHSHINE_COLOUR, render_seed
from scgen.render.lighting import body_albedo_light, sun_render_irradiance
from scgen.render.objects import object_parts
from scgen.render.props import prop_mesh
from scgen.render.region import Region, full_frame, paste
from scgen.scenes.finish import finished
from scgen.scenes.model import TargetModel
from scgen.scenes.spec import CameraSpec, SceneSpec

BEAUTY, PROBE, ALONE = "beauty", "probe", "alone"  # view layer names, prefixes of the EXR channels
MISS_DEPTH = 1e10  # Cycles' Z pass where a pixel's centred ray meets nothing


class BlenderScene:
    """Both scenes of one worker; `update(spec)` then `render_beauty()` / `render_aux()`."""

    def __init__(
        self,
        bpy: ModuleType,
        model: TargetModel,
        quality: QualityPreset,
        gpu: bool,
        threads: int | None,
        workdir: Path,
        models: Mapping[int, TargetModel],
    ) -> None:
        """`models`: every object's model by obj_id, for SceneSpec.objects."""
        from mathutils import Matrix

        self._bpy, self._Matrix, self._models = bpy, Matrix, models
        self.beauty_exr, self.aux_exr = workdir / "beauty.exr", workdir / "aux.exr"
        self.beauty = bpy.context.scene
        self.beauty.name = "scgen"
        self.aux = bpy.data.scenes.new("scgen_aux")
        configure_common(self.beauty, gpu, threads, str(self.beauty_exr))
        configure_beauty(self.beauty, quality, gpu)
        configure_common(self.aux, gpu, threads, str(self.aux_exr))
        configure_aux(self.aux)
        world = bpy.data.worlds.new("black")
        world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
        self.beauty.world = self.aux.world = world

        self.materials = build_materials(bpy, model.diameter)
        self._diameter = model.diameter
        self._finishes: dict[str, Any] = {}  # the target's own materials, made as finishes need them
        self.target_coll = bpy.data.collections.new("target")
        self.props_coll = bpy.data.collections.new("props")
        for scene in (self.beauty, self.aux):
            scene.collection.children.link(self.target_coll)
            scene.collection.children.link(self.props_coll)
        self.camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
        self.camera.matrix_world = Matrix(camera_matrix_world(np.eye(3), np.zeros(3)).tolist())
        self.camera.data.sensor_fit = "HORIZONTAL"
        self.camera.data.clip_start, self.camera.data.clip_end = CLIP_START_M, CLIP_END_M
        for scene in (self.beauty, self.aux):
            scene.collection.objects.link(self.camera)
            scene.camera = self.camera
        self.target = self._target_object(model)
        # Blender ignores shadow linking while the blocker collection is empty, and the target would
        # then shadow itself in the probe on a first sample without props: the pool starts non-empty
        self.props: list[Any] = [self._new_prop(0)]
        self.props[0].hide_render = True
        self.sun = self._sun("sun", self.beauty, SUN_ANGLE_RAD)
        self.earthshine = self._sun("earthshine", self.beauty, SUN_ANGLE_RAD)
        self.earthshine.data.color = EARTHSHINE_COLOUR
        self.probe = self._sun("probe", self.aux, 0.0)
        self.probe.light_linking.blocker_collection = self.props_coll  # the target never shadows itself here

        self.beauty.view_layers[0].name = BEAUTY
        override = probe_material(bpy)
        probe = self.aux.view_layers[0]
        probe.name = PROBE
        probe.use_pass_normal = True
        self.alone = self.aux.view_layers.new(ALONE)
        self.alone.use_pass_z = True
        self.alone.layer_collection.children[self.props_coll.name].exclude = True
        probe.material_override = self.alone.material_override = override
        self._camera_key: tuple | None = None
        self.regions: tuple[Region, ...] = (full_frame(1, 1),)  # the last beauty render's, for tests
        self.cycles_s = 0.0  # time inside bpy.ops.render.render, for benchmarks

    def update(self, spec: SceneSpec) -> None:
        """Move and re-light everything for `spec`."""
        self._set_camera(spec.camera)
        self.target.matrix_world = self._Matrix(spec.target.matrix.tolist())
        self._set_props(spec)
        self._set_lights(spec)
        self._set_finish(spec.finish)
        self.beauty.cycles.seed = render_seed(spec)

    @staticmethod
    def _set_border(scene: Any, region: Region) -> None:
        r = scene.render
        r.use_border = r.use_crop_to_border = not region.full
        if not region.full:
            r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = border_fractions(region)

    def render_beauty(self, regions: tuple[Region, ...]) -> dict[str, np.ndarray]:
        """The beauty passes over `regions` (disjoint) of the frame."""
        self.regions = regions
        return self._render(self.beauty, self.beauty_exr, regions)

    def render_aux(self, target_alone: bool, regions: tuple[Region, ...]) -> dict[str, np.ndarray]:
        """The aux passes over `regions` (disjoint); the `alone` layer (target-alone depth) only when
        `target_alone`. Each pixel's one centred sample is the same whatever else is traced."""
        self.alone.use = target_alone
        return self._render(self.aux, self.aux_exr, regions)

    def _render(self, scene: Any, path: Path, regions: tuple[Region, ...]) -> dict[str, np.ndarray]:
        """Render `regions` of `scene` to its EXR, each with a render call of its own (Cycles' border,
        cropped), and read them back: {'layer.Pass.C': H x W float32}, row 0 at the top, the full frame,
        every pixel outside the regions as a pixel that meets nothing renders."""
        crops = []
        for region in regions:
            self._set_border(scene, region)
            crops.append(self._render_call(scene, path))
        if len(regions) == 1 and regions[0].full:
            return crops[0]
        fill = {name: MISS_DEPTH if name.endswith("Depth.Z") else 0.0 for name in crops[0]}
        return {name: paste(regions, [c[name] for c in crops], fill[name]) for name in crops[0]}

    def _render_call(self, scene: Any, path: Path) -> dict[str, np.ndarray]:
        """One render of `scene` as its border stands, read back from its EXR."""
        t = time.perf_counter()
        with quiet_stdout():
            self._bpy.ops.render.render(write_still=True, scene=scene.name)
        self.cycles_s += time.perf_counter() - t
        with OpenEXR.File(str(path), separate_channels=True) as f:
            return {name: ch.pixels for part in f.parts for name, ch in part.channels.items()}

    def _target_object(self, model: TargetModel) -> Any:
        """One mesh object for the whole target, one material slot per material class in use."""
        bpy = self._bpy
        names = self.target_classes = sorted({material for material, _ in model.parts})
        offsets = np.cumsum([0] + [len(m.vertices) for _, m in model.parts])[:-1]
        vertices = np.concatenate([m.vertices for _, m in model.parts])
        faces = np.concatenate([m.faces + off for (_, m), off in zip(model.parts, offsets, strict=True)])
        slots = np.concatenate([np.full(len(m.faces), names.index(mat)) for mat, m in model.parts])
        mesh = bpy.data.meshes.new("target")
        set_triangles(mesh, vertices, faces)
        self._slots = [self.materials[name] for name in names]  # what _set_finish last gave each slot
        for name in names:
            mesh.materials.append(self.materials[name])
        mesh.polygons.foreach_set("material_index", slots.astype(np.int32))
        obj = bpy.data.objects.new("target", mesh)
        obj.pass_index = TARGET_ID
        self.target_coll.objects.link(obj)
        return obj

    def _set_finish(self, finish: dict[str, dict]) -> None:
        """The target's slots take the sample's finish (scgen.scenes.finish); nominal: the class materials."""
        slots = self.target.data.materials
        for k, cls in enumerate(self.target_classes):
            mat = self.materials[cls]
            if cls in finish:
                material = finished(finish, cls)
                name = f"target_{cls}_{finish[cls]['material']}"
                if name not in self._finishes:
                    self._finishes[name] = new_material(self._bpy, name, material, self._diameter)
                mat = self._finishes[name]
                set_finish(mat, material, self._diameter)
            if self._slots[k] is not mat:  # only what a finish changed: the slots stay the caller's otherwise
                slots[k] = self._slots[k] = mat

    def _sun(self, name: str, scene: Any, angle: float) -> Any:
        light = self._bpy.data.lights.new(name, "SUN")
        light.angle = angle
        obj = self._bpy.data.objects.new(name, light)
        scene.collection.objects.link(obj)
        return obj

    def _set_camera(self, cam: CameraSpec) -> None:
        key = (cam.width, cam.height, cam.K)
        if key == self._camera_key:
            return
        intr = intrinsics_from_K(cam.K_mat, cam.width, cam.height)
        data = self.camera.data
        data.sensor_width, data.lens = intr.sensor_width_mm, intr.lens_mm
        data.shift_x, data.shift_y = intr.shift_x, intr.shift_y
        for scene in (self.beauty, self.aux):
            scene.render.resolution_x, scene.render.resolution_y = cam.width, cam.height
        self._camera_key = key

    def _set_props(self, spec: SceneSpec) -> None:
        """The pool's objects take the props, then the labelled objects' parts beside the target (one pool
        object per part: a material each), in the props collection, so they shade and hide the target as
        props do and the `alone` layer leaves them out."""
        placed = []
        for k, prop in enumerate(spec.props):
            mesh = prop_mesh(prop)  # the shared geometry, in the camera frame: back to the prop's frame,
            local = (np.asarray(mesh.vertices) - prop.pose.t_vec) @ prop.pose.R_mat  # so textures stick to it
            instance = prop_instance_id(len(spec.objects), k)
            placed.append((local, mesh.faces, prop.pose, prop.material, instance))
        for part in object_parts(spec, self._models):
            placed.append((part.mesh.vertices, part.mesh.faces, part.pose, part.material, part.instance))
        for k, (vertices, faces, pose, material, instance) in enumerate(placed):
            if k == len(self.props):
                self.props.append(self._new_prop(k))
            obj = self.props[k]
            set_triangles(obj.data, vertices, faces)
            obj.matrix_world = self._Matrix(pose.matrix.tolist())
            obj.data.materials[0] = self.materials[material]
            obj.pass_index = instance
            obj.hide_render = False
        for obj in self.props[len(placed) :]:
            obj.hide_render = True

    def _new_prop(self, k: int) -> Any:
        mesh = self._bpy.data.meshes.new(f"prop{k}")
        mesh.materials.append(self.materials["white_paint"])
        obj = self._bpy.data.objects.new(f"prop{k}", mesh)
        self.props_coll.objects.link(obj)
        return obj

    def _set_lights(self, spec: SceneSpec) -> None:
        sun = np.asarray(spec.sun.direction, np.float64)
        self.sun.matrix_world = self.probe.matrix_world = self._Matrix(light_matrix_world(sun).tolist())
        self.sun.data.energy = sun_render_irradiance(spec)  # Cycles: white Lambert radiance = strength / pi
        albedo = body_albedo_light(spec)
        self.earthshine.hide_render = albedo is None
        if albedo is not None:
            direction, irradiance = albedo
            self.earthshine.matrix_world = self._Matrix(light_matrix_world(direction).tolist())
            self.earthshine.data.energy = irradiance
            self.earthshine.data.angle = 2.0 * np.deg2rad(spec.background.params["angular_radius_deg"])


def border_fractions(region: Region) -> tuple[float, float, float, float]:
    """Blender's border for `region`: min x, max x, min y, max y as fractions of the frame, y from the
    bottom. Blender truncates fraction x size (float32) to a pixel edge, so a fraction of exactly
    edge / size can land one pixel short; each is given half a pixel past its edge instead, which float32
    rounding (relative 6e-8, under 5e-4 px for any frame up to 8192 px) cannot carry across a pixel."""
    W, H = region.width, region.height
    x = [min(1.0, (edge + 0.5) / W) for edge in (region.x0, region.x1)]
    y = [min(1.0, (edge + 0.5) / H) for edge in (H - region.y1, H - region.y0)]
    return x[0], x[1], y[0], y[1]


def set_triangles(mesh: Any, vertices: np.ndarray, faces: np.ndarray) -> None:
    """Replace a mesh datablock's geometry in place with flat-shaded triangles (keeps its materials)."""
    n_faces = len(faces)
    mesh.clear_geometry()
    mesh.vertices.add(len(vertices))
    mesh.loops.add(3 * n_faces)
    mesh.polygons.add(n_faces)
    mesh.vertices.foreach_set("co", np.asarray(vertices, np.float32).ravel())
    mesh.polygons.foreach_set("loop_start", np.arange(0, 3 * n_faces, 3, dtype=np.int32))
    mesh.polygons.foreach_set("vertices", np.asarray(faces, np.int32).ravel())
    mesh.shade_flat()
    mesh.update(calc_edges=True)
