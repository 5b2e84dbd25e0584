"""Mitsuba 3 backend: fast CPU renders for tests and an independent cross-check of Blender.

RGB comes from Mitsuba's path tracer; the geometric passes (depth, instance ids, normals,
the target-alone depth, shadow rays) come from exact ray casts through pixel centres, so no
filtered or jittered sample ever blends two surfaces at an edge.

A worker keeps one scene (per camera, with or without the Earth's light) for its whole run and refills it
every sample: the target's triangles go into one mesh per finish BSDF, the props' into one mesh per
material class (slots), and the lights take the sample's direction and irradiance. Then the render
replays a frozen recording (drjit.freeze) instead of tracing the path tracer through every live BSDF
again (about 20 ms a sample at any image size); it records again only when the set of meshes, BSDFs or
lights grows, a mesh outgrows its capacity, or the film takes a new size (the lights' bounding sphere is
one for every sample, mitsuba.lights.steady_light_bounds).

The path tracer renders only a window over the region the objects cover (scgen.render.region,
mitsuba.window): the film is transparent and the sky is composited in numpy, so every pixel outside it
renders zero. The label passes are cast through every pixel, as before; they do not change.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import drjit as dr
import mitsuba as mi
import numpy as np
from trimesh.transformations import transform_points

from scgen.io.bop import TARGET_OBJ_ID
from scgen.io.buffers import BACKGROUND_ID, TARGET_ID, Buffers, prop_instance_id
from scgen.render.camera import record_image, render_camera
from scgen.render.conventions import CLIP_END_M, CLIP_START_M, MITSUBA_THREADS, check_quality, render_seed
from scgen.render.mitsuba.lights import SceneLights, sample_lights
from scgen.render.mitsuba.materials import TargetFinishes, box_uv, build_bsdfs, texture_scale
from scgen.render.mitsuba.ray_cull import may_hit
from scgen.render.mitsuba.raycast import cast_rays, intersect_from_origin, select_variant
from scgen.render.mitsuba.slots import MeshSlot, build_mesh
from scgen.render.mitsuba.window import PIXEL_FILTER, REACH_PX, film_window
from scgen.render.objects import model_hulls, object_parts, objects_alone_depth, with_target
from scgen.render.props import prop_mesh
from scgen.render.region import Region, full_frame, region_render, scene_region
from scgen.render.sky.backgrounds import background_image
from scgen.scenes.model import TargetModel
from scgen.scenes.spec import CameraSpec, SceneSpec

QUALITY_SPP = {"draft": 4, "default": 16, "high": 64}
GUARD_M = 1e4  # half the span of the guard triangle (see MitsubaBackend.__init__)
PROP_SLOT_TRIANGLES = 4096  # a material's prop mesh holds this many triangles at first (it grows if need be)
FINISHES_PER_CLASS = 3  # target BSDFs (and meshes) made per material class at the start (see TargetFinishes)
# the path tracer's longest path in vertices: the sun's direct light and two bounces (Mitsuba counts the
# camera ray's hit as depth 1); benchmarks/probes/mitsuba_depth.py measures the others against 512 spp
PATH_MAX_DEPTH = 4
RECORDINGS_KEPT = 32  # frozen renders a backend keeps, the least recently used dropped first


class SampleMeshes:
    """Where a sample's shapes went: the target's slots (one per part class, in the model's class order)
    and the props' (one per material with any; the other labelled objects' parts go there too), with the
    instance each of their triangles belongs to."""

    def __init__(self) -> None:
        self.target: list[MeshSlot] = []
        self.props: list[MeshSlot] = []
        self.owners: list[np.ndarray] = []  # per prop mesh: the instance id (scgen.io.buffers) per triangle
        self.target_corners: list[np.ndarray] = []  # per target slot: its triangles' corners (3F x 3)


class MitsubaBackend:
    """Renders SceneSpecs with Mitsuba; one instance per worker process."""

    name = "mitsuba"

    def __init__(
        self,
        model: TargetModel,
        quality: str = "default",
        threads: int = MITSUBA_THREADS,
        region: bool | None = None,
        models: Mapping[int, TargetModel] | None = None,
    ) -> None:
        """`threads`: Dr.Jit's CPU threads, for the whole process (above MITSUBA_THREADS, see there);
        `region`: path-trace only a window over the pixels the objects may cover (mitsuba.window), else
        the whole frame (None: as region_render() says); `models`: every object's model by obj_id, for
        SceneSpec.objects (None: the target's alone)."""
        self.variant = select_variant()
        dr.set_thread_count(threads)
        self.model = model
        check_quality(quality)
        self.spp = QUALITY_SPP[quality]
        self.bsdfs = build_bsdfs()
        self._classes: dict[str, list[int]] = {}  # material class -> its parts, one target mesh each
        for k, (material, _) in enumerate(model.parts):
            self._classes.setdefault(material, []).append(k)
        self._uv: dict[tuple[int, int, str], np.ndarray] = {}  # (obj_id, part, class rendered) -> UVs
        self._finishes = TargetFinishes(FINISHES_PER_CLASS)
        self._reach = 1.01 * float(np.linalg.norm(model.mesh.vertices, axis=1).max())  # target's radius
        self.models = with_target(model, models)
        self._hulls = model_hulls(self.models)
        self.trace_region = region_render() if region is None else region
        self.window = full_frame(1, 1)  # the last render's film window, for tests and benchmarks
        # the target's slots, one per BSDF it is drawn with (named as TargetFinishes names them, or by the
        # nominal class), each large enough for the largest part class; the props', one per material class
        self._target_capacity = max(
            sum(len(model.parts[k][1].faces) for k in ks) for ks in self._classes.values()
        )
        self._target_slots = {
            name: MeshSlot(f"target_{name}", bsdf, self._target_capacity)
            for name, bsdf in self._finishes.pooled()
        }
        self._prop_slots = {m: MeshSlot(f"props_{m}", b, PROP_SLOT_TRIANGLES) for m, b in self.bsdfs.items()}
        # the target's triangles that rays meeting a prop first may hit, cast again through the target alone
        self._target_alone = MeshSlot("target_alone", self.bsdfs["white_paint"], len(model.mesh.faces))
        # one triangle of no area, never hit, whose box spans 20 km: beside it Embree finds no spatial
        # split worth making, and builds the target's BVH in 8 ms instead of 19 (labels are the same)
        far = GUARD_M * np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, -1.0], [1.0, 1.0, -1.0]])
        self._guard = build_mesh("guard", far, np.zeros((3, 2)), self.bsdfs["white_paint"])
        # the path tracer's scenes, by (camera, with the Earth's light), with their lights
        self._scenes: dict[tuple, tuple[mi.Scene, SceneLights]] = {}
        self._cast_scenes: dict[str, mi.Scene] = {}  # ray-cast scenes kept likewise (see _cast_scene)
        self._window_sensors: dict[CameraSpec, mi.Sensor] = {}  # one per render camera (_window_sensor)
        # this backend's own recordings: they hold the addresses of its meshes' buffers, which another
        # backend's meshes in the same layout would not have
        self._frozen_render = dr.freeze(_render_scene, limit=RECORDINGS_KEPT, warn_after=2**31 - 1)
        self._frozen_intersect = dr.freeze(intersect_from_origin, limit=RECORDINGS_KEPT, warn_after=2**31 - 1)
        # the window renders' (trace_region), one frozen function per film size (each compiled with its
        # own constants): in one function, a call with another sensor than the last would record again
        self._frozen_windows: dict[tuple[int, int], Any] = {}

    def close(self) -> None:
        pass

    @property
    def recordings(self) -> int:
        """How many renders traced the path tracer and recorded it; every other render replayed one."""
        if not dr.is_jit_v(mi.Float):
            return 0
        return sum(f.n_recordings for f in (self._frozen_render, *self._frozen_windows.values()))

    def _fill(self, spec: SceneSpec, shaded: bool = True) -> SampleMeshes:
        """Put the sample's target and props, in the camera frame, into their slots. `shaded`: the target
        with the sample's finish (else the nominal BSDFs)."""
        T = spec.target.matrix
        finish = {cls: f for cls, f in spec.finish.items() if cls in self._classes} if shaded else {}
        dr.sync_thread()  # no kernel still reads what this sample overwrites (its meshes, finishes, lights)
        drawn_with = self._finishes.bsdfs(finish)
        layout, filled = SampleMeshes(), set()
        for cls, parts in self._classes.items():
            name, bsdf = drawn_with.get(cls, (cls, self.bsdfs[cls]))
            if name not in self._target_slots:
                self._target_slots[name] = MeshSlot(f"target_{name}", bsdf, self._target_capacity)
                self._scenes.clear()  # a new mesh: every scene is rebuilt with it
                self._cast_scenes.clear()
            drawn = spec.finish[cls]["material"] if cls in spec.finish else cls
            corners = np.concatenate([transform_points(mesh.vertices, T)[mesh.faces].reshape(-1, 3)
                                      for mesh in (self.model.parts[k][1] for k in parts)])  # fmt: skip
            uv = np.concatenate([self._part_uv(TARGET_OBJ_ID, k, drawn) for k in parts])
            slot = self._target_slots[name]
            slot.fill(corners, uv)
            filled.add(name)
            layout.target.append(slot)
            layout.target_corners.append(corners)
        for name, slot in self._target_slots.items():
            if name not in filled:
                slot.fill(np.zeros((0, 3)), np.zeros((0, 2)))
        by_material: dict[str, list[tuple[int, np.ndarray, np.ndarray]]] = {}
        for k, prop in enumerate(spec.props):
            m = prop_mesh(prop)
            local = (np.asarray(m.vertices) - prop.pose.t_vec) @ prop.pose.R_mat  # UVs stick to the prop
            uv = box_uv(local, np.asarray(m.faces), texture_scale(prop.material, max(prop.size)))
            corners = np.asarray(m.vertices)[np.asarray(m.faces)].reshape(-1, 3)
            instance = prop_instance_id(len(spec.objects), k)
            by_material.setdefault(prop.material, []).append((instance, corners, uv))
        for part in object_parts(spec, self.models):
            uv = self._part_uv(part.obj_id, part.part, part.material)
            corners = transform_points(part.mesh.vertices, part.pose.matrix)[part.mesh.faces].reshape(-1, 3)
            by_material.setdefault(part.material, []).append((part.instance, corners, uv))
        for material, slot in self._prop_slots.items():
            pieces = by_material.get(material, [])
            slot.fill(np.concatenate([c for _, c, _ in pieces] or [np.zeros((0, 3))]),
                      np.concatenate([uv for _, _, uv in pieces] or [np.zeros((0, 2))]))  # fmt: skip
            if pieces:
                layout.props.append(slot)
                layout.owners.append(np.concatenate([np.full(len(c) // 3, k) for k, c, _ in pieces]))
        return layout

    def _part_uv(self, obj_id: int, k: int, material: str) -> np.ndarray:
        """Object `obj_id`'s part k's UVs, scaled for the material class it is rendered with."""
        if (obj_id, k, material) not in self._uv:
            model = self.models[obj_id]
            mesh = model.parts[k][1]
            scale = texture_scale(material, model.diameter)
            self._uv[obj_id, k, material] = box_uv(np.asarray(mesh.vertices), np.asarray(mesh.faces), scale)
        return self._uv[obj_id, k, material]

    def render(self, spec: SceneSpec) -> Buffers:
        layout = self._fill(spec)
        scene = self._scene(spec)
        buffers = self._passes(spec, scene, layout)
        buffers.rgb, buffers.camera = record_image(spec, self._shade(spec, scene), buffers.instance)
        return buffers

    def render_geometry(self, spec: SceneSpec) -> Buffers:
        """Only the exact geometric passes (RGB left black): labels at a fraction of the cost."""
        layout = self._fill(spec, shaded=False)
        return self._passes(spec, self._cast_scene("all", self._slots()), layout)

    def _passes(self, spec: SceneSpec, scene: mi.Scene, layout: SampleMeshes) -> Buffers:
        """The exact geometric passes of `scene` (holding `layout`'s meshes): one ray per pixel centre.

        The target-alone depth equals the depth wherever the target is hit first; only the rays that hit
        a prop no farther than the target's bounding sphere reaches are cast again, through the target alone.
        """
        W, H = spec.camera.width, spec.camera.height
        rays_cam = spec.camera.pixel_directions().reshape(-1, 3)
        shapes = layout.target + layout.props
        t_all, idx_all, normal, prim = cast_rays(scene, shapes, rays_cam, self._intersect)
        n_target = len(layout.target)
        hit = idx_all >= 0
        on_target = hit & (idx_all < n_target)
        on_prop = hit & ~on_target
        t_tgt = np.where(on_target, t_all, np.inf)
        behind = on_prop & self._may_reach_target(spec, rays_cam, t_all)
        if behind.any():  # as many rays as the image has (the first repeated), so one recording serves all
            chosen = rays_cam[behind]
            rays = np.concatenate([chosen, np.repeat(chosen[:1], len(rays_cam) - len(chosen), axis=0)])
            corners = np.concatenate(layout.target_corners)
            kept = np.repeat(may_hit(corners.reshape(-1, 3, 3), chosen), 3)
            dr.sync_thread()  # the last sample's cast through the target alone is done with its buffers
            self._target_alone.fill(corners[kept], np.zeros((int(kept.sum()), 2)))
            target = self._cast_scene("target", [self._target_alone])
            t_tgt[behind] = cast_rays(target, [], rays, self._intersect)[0][: len(chosen)]
        z_scale = rays_cam[:, 2]
        depth = np.where(np.isfinite(t_all), t_all * z_scale, 0.0).reshape(H, W).astype(np.float32)
        target_depth = np.where(np.isfinite(t_tgt), t_tgt * z_scale, 0.0).reshape(H, W).astype(np.float32)
        instance = np.full(H * W, BACKGROUND_ID, np.int32)
        instance[on_target] = TARGET_ID
        for j, owners in enumerate(layout.owners):
            on_mesh = idx_all == n_target + j
            instance[on_mesh] = owners[prim[on_mesh]]
        normal = np.where((np.sum(normal * rays_cam, axis=1) > 0)[:, None], -normal, normal)

        sun = np.asarray(spec.sun.direction, np.float64)
        sun_blocked = np.zeros(H * W, bool)
        if layout.props and on_target.any():
            origins = rays_cam[on_target] * t_all[on_target, None] + 1e-4 * normal[on_target]
            props = self._cast_scene("props", list(self._prop_slots.values()))
            sun_blocked[on_target] = _occluded(props, origins, sun)

        return Buffers(
            rgb=np.zeros((H, W, 3), np.uint8),
            depth=depth,
            instance=instance.reshape(H, W),
            target_depth=target_depth,
            normal=np.where(on_target[:, None], normal, 0.0).reshape(H, W, 3).astype(np.float32),
            sun_blocked=sun_blocked.reshape(H, W),
            objects_depth=objects_alone_depth(spec, self.models),
        )

    def _cast_scene(self, name: str, slots: list[MeshSlot]) -> mi.Scene:
        """A scene of these slots (and the guard) for ray casts, kept from sample to sample under `name`
        so that its casts replay frozen; its BVH rebuilt for the refilled slots."""
        if name not in self._cast_scenes:
            self._cast_scenes[name] = self._scene_of([slot.mesh for slot in slots])
        else:
            self._rebuild(self._cast_scenes[name])
        return self._cast_scenes[name]

    def _rebuild(self, scene: mi.Scene) -> None:
        """Rebuild a kept scene's BVH for its slots' new triangles. The slots are written without telling
        them (slots), so the guard is touched: a scene rebuilds when any of its shapes changed, and
        another scene's rebuild marks the guard up to date again."""
        self._guard.parameters_changed(["vertex_positions"])
        scene.parameters_changed([])

    def _scene_of(self, shapes: list[mi.Mesh]) -> mi.Scene:
        """A scene of these meshes alone (and the guard), for ray casts."""
        shapes = [*shapes, self._guard]
        return mi.load_dict({"type": "scene", **{f"s{k:03d}": s for k, s in enumerate(shapes)}})

    def _may_reach_target(self, spec: SceneSpec, rays: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Whether each ray (unit directions from the camera) meets the target's bounding sphere (about
        its origin, 1 % wider) anywhere beyond distance t."""
        centre = np.asarray(spec.target.t_vec, np.float64)
        along = rays @ centre
        gap2 = centre @ centre - along**2  # squared distance from the sphere's centre to the ray's line
        return (gap2 <= self._reach**2) & (t <= along + np.sqrt(np.maximum(self._reach**2 - gap2, 0.0)))

    def _scene(self, spec: SceneSpec) -> mi.Scene:
        """The path tracer's scene, holding every slot (filled for `spec`), the sun (and earthshine), the
        render camera (scgen.render.camera.lens) and its film: built once per camera and Earth's light,
        then given each sample's lights; its BVH is rebuilt for the refilled meshes."""
        lights, camera = sample_lights(spec), render_camera(spec.camera)
        key = (camera, tuple(lights))
        if key not in self._scenes:
            sensor = _sensor(camera, self.spp)
            integrator = {"type": "path", "max_depth": PATH_MAX_DEPTH}
            d = {"type": "scene", "integrator": integrator, "sensor": sensor, **lights}
            d.update({f"s{k:03d}": slot.mesh for k, slot in enumerate(self._slots())}, guard=self._guard)
            scene = mi.load_dict(d)
            self._scenes[key] = scene, SceneLights(scene, list(lights))
        else:
            self._rebuild(self._scenes[key][0])
        scene, scene_lights = self._scenes[key]
        scene_lights.set(lights)
        return scene

    def _shade(self, spec: SceneSpec, scene: mi.Scene) -> np.ndarray:
        """The linear composite over the background, on the render camera (scgen.render.camera.lens)."""
        shown = replace(spec, camera=render_camera(spec.camera))
        self.window = film_window(self.region(shown))
        img = np.asarray(self._render(shown, scene, self.window), dtype=np.float32)
        img = self.window.paste(img, 0.0)  # a pixel outside renders (0, 0, 0, 0): it meets nothing
        fg, alpha = img[..., :3], img[..., 3:4]
        return fg + (1.0 - np.clip(alpha, 0, 1)) * background_image(shown)

    def region(self, spec: SceneSpec) -> Region:
        """The pixels of `spec`'s frame (its render camera's) whose value the objects may set."""
        if not self.trace_region:
            return full_frame(spec.camera.width, spec.camera.height)
        return scene_region(spec, self._hulls, REACH_PX, 0)

    def _window_sensor(self, camera: CameraSpec, window: Region) -> mi.Sensor:
        """The window's camera: one sensor kept per render camera and set to the window, its film's size
        and its field of view and principal point (opaque values, not a recording's constants). One, not
        one per window size: with a sensor per size the renders recorded again more often."""
        d = _sensor(camera, self.spp, window)
        if not dr.is_jit_v(mi.Float):  # scalar_rgb: no recording to keep, a new sensor
            return mi.load_dict(d)
        if camera not in self._window_sensors:
            self._window_sensors[camera] = mi.load_dict(d)
        params = mi.traverse(self._window_sensors[camera])
        size = mi.ScalarVector2u(d["film"]["width"], d["film"]["height"])
        params["film.size"] = params["film.crop_size"] = size
        params["x_fov"] = dr.opaque(mi.Float, d["fov"])
        for axis in "xy":
            params[f"principal_point_offset_{axis}"] = dr.opaque(
                mi.Float, d[f"principal_point_offset_{axis}"]
            )
        params.update()
        return self._window_sensors[camera]

    def _intersect(self, scene: mi.Scene, d: mi.Vector3f) -> tuple:
        """intersect_from_origin, replayed from a frozen recording: keyed by the meshes' capacities (their
        buffers' addresses) and the ray count (never left to the recording's size inference)."""
        return self._frozen_intersect(scene, d, capacities=self._capacities(), rays=dr.width(d))

    def _slots(self) -> list[MeshSlot]:
        """Every slot, the target's then the props'."""
        return [*self._target_slots.values(), *self._prop_slots.values()]

    def _capacities(self) -> tuple[int, ...]:
        return tuple(s.capacity for s in self._slots())

    def _render(self, spec: SceneSpec, scene: mi.Scene, window: Region) -> mi.TensorXf:
        """mi.render of `window` of `scene`'s frame (`spec` on its render camera), replayed from a frozen
        recording in a JIT variant. Its inputs name every live object the recorded kernels call into (the
        other scenes' lights too) and, as plain values, what the recording bakes in: the meshes'
        capacities and the film's size (the lights' bounding sphere is one for all: steady_light_bounds)."""
        sensor = self._window_sensor(spec.camera, window) if self.trace_region else 0  # 0: the scene's own
        if not dr.is_jit_v(mi.Float):
            return mi.render(scene, sensor=sensor, seed=render_seed(spec))
        others = [e for other, _ in self._scenes.values() if other is not scene for e in other.emitters()]
        seed = dr.opaque(mi.UInt32, render_seed(spec))
        capacities = self._capacities()
        if not self.trace_region:
            return self._frozen_render(scene, seed, capacities, others)
        film = (window.x1 - window.x0, window.y1 - window.y0)
        if film not in self._frozen_windows:  # every input opaque: a size's few renders learn nothing
            self._frozen_windows[film] = dr.freeze(
                _render_scene, limit=RECORDINGS_KEPT, warn_after=2**31 - 1, auto_opaque=False
            )
        return self._frozen_windows[film](scene, seed, capacities, others, sensor=sensor)


def _render_scene(
    scene: mi.Scene, seed: mi.UInt32, capacities: tuple, others: list, sensor: Any = 0
) -> mi.TensorXf:
    """mi.render through `sensor` (the scene's own, or another), to be frozen: recorded once per distinct
    set of inputs, replayed after (see MitsubaBackend._render)."""
    return mi.render(scene, sensor=sensor, seed=seed)


def _sensor(cam, spp: int, window: Region | None = None) -> dict:
    """The render camera as Mitsuba's perspective sensor, with its film and sampler; with `window`, a
    camera of the window's pixels of the frame (the same rays through them)."""
    K = cam.K_mat
    window = window or full_frame(cam.width, cam.height)
    width, height = window.x1 - window.x0, window.y1 - window.y0
    cx, cy = K[0, 2] - window.x0, K[1, 2] - window.y0
    return {
        "type": "perspective",
        "fov": float(np.degrees(2 * np.arctan(width / (2 * K[0, 0])))),
        "fov_axis": "x",
        "principal_point_offset_x": ((width - 1) / 2 - cx) / width,
        "principal_point_offset_y": ((height - 1) / 2 - cy) / height,
        "near_clip": CLIP_START_M,
        "far_clip": CLIP_END_M,
        "to_world": mi.ScalarTransform4f().scale([-1, -1, 1]),
        "film": {
            "type": "hdrfilm",
            "width": width,
            "height": height,
            "pixel_format": "rgba",
            "rfilter": dict(PIXEL_FILTER),
        },
        "sampler": {"type": "independent", "sample_count": spp},
    }


def _occluded(scene: mi.Scene, origins: np.ndarray, direction: np.ndarray) -> np.ndarray:
    if len(origins) == 0:
        return np.zeros(0, bool)
    if not dr.is_jit_v(mi.Float):  # scalar_rgb: one ray at a time
        d = mi.Vector3f(direction.tolist())
        return np.array([scene.ray_test(mi.Ray3f(mi.Point3f(o), d)) for o in origins.tolist()], bool)
    ray = mi.Ray3f(
        mi.Point3f(origins[:, 0], origins[:, 1], origins[:, 2]),
        mi.Vector3f(*[np.full(len(origins), float(x)) for x in direction]),
    )
    return np.asarray(scene.ray_test(ray), bool)
