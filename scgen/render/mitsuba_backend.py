"""Mitsuba 3 backend: fast CPU renders for tests and an independent cross-check of Blender.

RGB comes from Mitsuba's path tracer; the geometric passes (depth, instance ids, normals,
the target-alone depth, shadow rays) come from exact ray casts through pixel centres, so no
filtered or jittered sample ever blends two surfaces at an edge.
"""

from __future__ import annotations

from dataclasses import replace

import drjit as dr
import mitsuba as mi
import numpy as np

from scgen.buffers import BACKGROUND_ID, TARGET_ID, Buffers
from scgen.model import TargetModel
from scgen.render.backgrounds import background_image
from scgen.render.camera import record_image, render_camera
from scgen.render.conventions import CLIP_END_M, CLIP_START_M, EARTHSHINE_COLOUR, check_quality, render_seed
from scgen.render.lighting import earth_albedo_light, sun_render_irradiance
from scgen.render.mitsuba_llvm import mitsuba_setup
from scgen.render.mitsuba_materials import TargetFinishes, box_uv, build_bsdfs, texture_scale
from scgen.render.props import prop_mesh
from scgen.scenes.finish import finished
from scgen.scenes.spec import SceneSpec

QUALITY_SPP = {"draft": 4, "default": 16, "high": 64}


def select_variant() -> str:
    """Set the variant mitsuba_llvm chose for this process (llvm_ad_rgb when its libLLVM renders, else
    scalar_rgb), unless one is set already; returns the variant in use."""
    if mi.variant() is None:
        mi.set_variant(mitsuba_setup().variant)
    return mi.variant()


def _mesh(name: str, vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, bsdf: mi.BSDF) -> mi.Mesh:
    """A Mitsuba mesh of unwelded triangles (3 vertices per face, as box_uv lays them out)."""
    props = mi.Properties()
    props["bsdf"] = bsdf
    m = mi.Mesh(name, 3 * len(faces), len(faces), props=props, has_vertex_normals=False,
                has_vertex_texcoords=True)  # fmt: skip
    params = mi.traverse(m)
    params["vertex_positions"] = dr.ravel(mi.TensorXf(vertices[faces].reshape(-1, 3).astype(np.float32)))
    params["faces"] = dr.ravel(mi.TensorXu(np.arange(3 * len(faces), dtype=np.uint32)))
    params["vertex_texcoords"] = dr.ravel(mi.TensorXf(uv.astype(np.float32)))
    params.update()
    return m


class MitsubaBackend:
    """Renders SceneSpecs with Mitsuba; one instance per worker process."""

    name = "mitsuba"

    def __init__(self, model: TargetModel, quality: str = "default", threads: int | None = None) -> None:
        self.variant = select_variant()
        if threads is not None:
            dr.set_thread_count(threads)
        self.model = model
        check_quality(quality)
        self.spp = QUALITY_SPP[quality]
        self.bsdfs = build_bsdfs()
        self._uv: dict[tuple[int, str], np.ndarray] = {}  # (part, class rendered) -> the part's UVs
        self._finishes = TargetFinishes()

    def close(self) -> None:
        pass

    def _shapes(self, spec: SceneSpec) -> tuple[list[mi.Mesh], list[mi.Mesh]]:
        """Mitsuba meshes of the target parts and of the props, in the camera frame."""
        T = spec.target.matrix
        target, props = [], []
        for k, (material, mesh) in enumerate(self.model.parts):
            m = mesh.copy()
            m.apply_transform(T)
            drawn = spec.finish[material]["material"] if material in spec.finish else material
            bsdf = self.bsdfs[material]
            if material in spec.finish:  # the sample's finish
                bsdf = self._finishes.bsdf(material, drawn, finished(spec.finish, material))
            target.append(_mesh(f"target{k}", np.asarray(m.vertices), np.asarray(m.faces),
                                self._part_uv(k, drawn), bsdf))  # fmt: skip
        for k, prop in enumerate(spec.props):
            m = prop_mesh(prop)
            local = (np.asarray(m.vertices) - prop.pose.t_vec) @ prop.pose.R_mat  # UVs stick to the prop
            uv = box_uv(local, np.asarray(m.faces), texture_scale(prop.material, max(prop.size)))
            props.append(_mesh(f"prop{k}", np.asarray(m.vertices), np.asarray(m.faces), uv,
                               self.bsdfs[prop.material]))  # fmt: skip
        return target, props

    def _part_uv(self, k: int, material: str) -> np.ndarray:
        """Target part k's UVs, scaled for the material class it is rendered with."""
        if (k, material) not in self._uv:
            mesh = self.model.parts[k][1]
            scale = texture_scale(material, self.model.diameter)
            self._uv[k, material] = box_uv(np.asarray(mesh.vertices), np.asarray(mesh.faces), scale)
        return self._uv[k, material]

    def render(self, spec: SceneSpec) -> Buffers:
        target, props = self._shapes(spec)
        buffers = self._passes(spec, target, props)
        buffers.rgb, buffers.camera = record_image(spec, self._shade(spec, target + props), buffers.instance)
        return buffers

    def render_geometry(self, spec: SceneSpec) -> Buffers:
        """Only the exact geometric passes (RGB left black): labels at a fraction of the cost."""
        return self._passes(spec, *self._shapes(spec))

    def _passes(self, spec: SceneSpec, target: list[mi.Mesh], props: list[mi.Mesh]) -> Buffers:
        geo_target = self._geometry_scene(target)
        geo_all = self._geometry_scene(target + props)
        geo_props = self._geometry_scene(props) if props else None

        W, H = spec.camera.width, spec.camera.height
        rays_cam = spec.camera.pixel_directions().reshape(-1, 3)
        t_all, idx_all, normal = cast_rays(geo_all, target + props, rays_cam)
        t_tgt, _, _ = cast_rays(geo_target, [], rays_cam)
        z_scale = rays_cam[:, 2]
        depth = np.where(np.isfinite(t_all), t_all * z_scale, 0.0).reshape(H, W).astype(np.float32)
        target_depth = np.where(np.isfinite(t_tgt), t_tgt * z_scale, 0.0).reshape(H, W).astype(np.float32)
        n_target = len(target)
        instance = np.full(H * W, BACKGROUND_ID, np.int32)
        hit = idx_all >= 0
        instance[hit & (idx_all < n_target)] = TARGET_ID
        is_prop = hit & (idx_all >= n_target)
        instance[is_prop] = 2 + (idx_all[is_prop] - n_target)
        normal = np.where((np.sum(normal * rays_cam, axis=1) > 0)[:, None], -normal, normal)

        sun = np.asarray(spec.sun.direction, np.float64)
        sun_blocked = np.zeros(H * W, bool)
        if geo_props is not None:
            pts = rays_cam * np.where(hit, t_all, 0.0)[:, None]
            on_target = instance == TARGET_ID
            origins = pts[on_target] + 1e-4 * normal[on_target]
            sun_blocked[on_target] = _occluded(geo_props, origins, sun)

        return Buffers(
            rgb=np.zeros((H, W, 3), np.uint8),
            depth=depth,
            instance=instance.reshape(H, W),
            target_depth=target_depth,
            normal=normal.reshape(H, W, 3).astype(np.float32),
            sun_blocked=sun_blocked.reshape(H, W),
        )

    @staticmethod
    def _geometry_scene(shapes: list[mi.Mesh]) -> mi.Scene:
        d = {"type": "scene"}
        for k, s in enumerate(shapes):
            d[f"s{k:03d}"] = s
        return mi.load_dict(d)

    def _shade(self, spec: SceneSpec, shapes: list[mi.Mesh]) -> np.ndarray:
        """The linear composite over the background, on the render camera (scgen.render.camera.lens)."""
        spec = replace(spec, camera=render_camera(spec.camera))
        cam = spec.camera
        K = cam.K_mat
        d: dict = {
            "type": "scene",
            "integrator": {"type": "path", "max_depth": 4},
            "sensor": {
                "type": "perspective",
                "fov": float(np.degrees(2 * np.arctan(cam.width / (2 * K[0, 0])))),
                "fov_axis": "x",
                "principal_point_offset_x": ((cam.width - 1) / 2 - K[0, 2]) / cam.width,
                "principal_point_offset_y": ((cam.height - 1) / 2 - K[1, 2]) / cam.height,
                "near_clip": CLIP_START_M,
                "far_clip": CLIP_END_M,
                "to_world": mi.ScalarTransform4f().scale([-1, -1, 1]),
                "film": {
                    "type": "hdrfilm",
                    "width": cam.width,
                    "height": cam.height,
                    "pixel_format": "rgba",
                    "rfilter": {"type": "gaussian"},
                },
                "sampler": {"type": "independent", "sample_count": self.spp},
            },
            "sun": {
                "type": "directional",
                "direction": [-float(x) for x in spec.sun.direction],
                "irradiance": {"type": "rgb", "value": sun_render_irradiance(spec)},
            },
        }
        albedo = earth_albedo_light(spec)
        if albedo is not None:
            direction, irradiance = albedo
            d["earthshine"] = {
                "type": "directional",
                "direction": [-float(x) for x in direction],
                "irradiance": {"type": "rgb", "value": [c * irradiance for c in EARTHSHINE_COLOUR]},
            }
        for k, s in enumerate(shapes):
            d[f"s{k:03d}"] = s
        scene = mi.load_dict(d)
        img = np.asarray(mi.render(scene, seed=render_seed(spec)), dtype=np.float32)
        fg, alpha = img[..., :3], img[..., 3:4]
        return fg + (1.0 - np.clip(alpha, 0, 1)) * background_image(spec)


def cast_rays(scene: mi.Scene, shapes: list, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ray length, index of the hit shape in `shapes` (-1 = miss) and geometric normal, rays from origin."""
    if not dr.is_jit_v(mi.Float):
        return _cast_rays_one_by_one(scene, shapes, dirs)
    o = mi.Point3f(0.0, 0.0, 0.0)
    ray = mi.Ray3f(o, mi.Vector3f(dirs[:, 0], dirs[:, 1], dirs[:, 2]))
    si = scene.ray_intersect(ray)
    valid = np.asarray(si.is_valid())
    t = np.where(valid, np.asarray(si.t, np.float64), np.inf)
    idx = np.full(len(dirs), -1, np.int64)
    if shapes:  # scene.shapes() is not in insertion order: map each hit's shape registry id to its index
        ids = np.array([_registry_id(mi.ShapePtr(s))[0] for s in shapes])
        hit_ids = _registry_id(si.shape)
        lut = np.full(max(int(ids.max()), int(hit_ids.max())) + 1, -1, np.int64)
        lut[ids] = np.arange(len(shapes))
        idx = np.where(valid, lut[hit_ids], -1)
    n = np.stack([np.asarray(si.n.x), np.asarray(si.n.y), np.asarray(si.n.z)], 1).astype(np.float64)
    return t, idx, np.where(valid[:, None], n, 0.0)


def _cast_rays_one_by_one(
    scene: mi.Scene, shapes: list, dirs: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """cast_rays for scalar_rgb (the fallback without a usable libLLVM), whose rays go one at a time."""
    index = {id(s): k for k, s in enumerate(shapes)}
    t, idx, n = np.full(len(dirs), np.inf), np.full(len(dirs), -1, np.int64), np.zeros((len(dirs), 3))
    o = mi.Point3f(0.0, 0.0, 0.0)
    for i, d in enumerate(dirs.tolist()):
        si = scene.ray_intersect(mi.Ray3f(o, mi.Vector3f(d)))
        if si.is_valid():
            t[i], idx[i], n[i] = si.t, index.get(id(si.shape), -1), si.n
    return t, idx, n


def _registry_id(ptr: mi.ShapePtr) -> np.ndarray:
    """Dr.Jit stores shape pointers as registry ids: one vectorised comparison instead of one per shape."""
    return np.asarray(dr.reinterpret_array(mi.UInt32, ptr)).astype(np.int64)


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
