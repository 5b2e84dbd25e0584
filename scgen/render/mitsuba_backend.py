"""Mitsuba 3 backend: fast CPU renders for tests and an independent cross-check of Blender.

RGB comes from Mitsuba's path tracer; the geometric passes (depth, instance ids, normals,
the target-alone depth, shadow rays) come from exact ray casts through pixel centres, so no
filtered or jittered sample ever blends two surfaces at an edge.
"""

from __future__ import annotations

import sys

import drjit as dr
import mitsuba as mi
import numpy as np
import trimesh

from scgen.model import TargetModel
from scgen.render.backgrounds import background_image, linear_to_srgb8
from scgen.render.base import BACKGROUND_ID, TARGET_ID, Buffers
from scgen.render.lighting import earth_albedo_light, sun_render_irradiance
from scgen.render.props import prop_mesh
from scgen.scenes.spec import SceneSpec

QUALITY_SPP = {"draft": 4, "default": 16, "high": 64}
_variant_notice_shown = False


def select_variant() -> str:
    """llvm_ad_rgb when libLLVM works, else scalar_rgb with a one-line notice."""
    global _variant_notice_shown
    if mi.variant() is not None:
        return mi.variant()
    try:
        mi.set_variant("llvm_ad_rgb")
        dr.eval(dr.llvm.Float([1.0]) * 2)  # forces LLVM to compile once
    except Exception as exc:  # missing/broken libLLVM
        mi.set_variant("scalar_rgb")
        if not _variant_notice_shown:
            print(f"scgen: Mitsuba LLVM variant unavailable ({exc}); using scalar_rgb", file=sys.stderr)
            _variant_notice_shown = True
    return mi.variant()


def _bsdf(material: str) -> dict:
    """Spacecraft material classes as Mitsuba BSDFs."""
    if material == "mli_gold":
        return {"type": "roughconductor", "material": "Au", "alpha": 0.25}
    if material == "mli_silver":
        return {"type": "roughconductor", "material": "Ag", "alpha": 0.2}
    if material == "brushed_metal":
        return {"type": "roughconductor", "material": "Al", "alpha": 0.15}
    if material == "solar_cell":
        return {
            "type": "principled",
            "base_color": {"type": "rgb", "value": [0.02, 0.03, 0.09]},
            "roughness": 0.15,
            "specular": 0.6,
        }
    if material == "dark_metal":
        return {
            "type": "principled",
            "base_color": {"type": "rgb", "value": [0.05, 0.05, 0.055]},
            "metallic": 0.5,
            "roughness": 0.4,
        }
    return {
        "type": "principled",
        "base_color": {"type": "rgb", "value": [0.75, 0.75, 0.72]},
        "roughness": 0.6,
    }


def _mesh(name: str, mesh: trimesh.Trimesh, material: str) -> mi.Mesh:
    m = mi.Mesh(name, len(mesh.vertices), len(mesh.faces), props=mi.Properties(), has_vertex_normals=False)
    params = mi.traverse(m)
    params["vertex_positions"] = dr.ravel(mi.TensorXf(np.asarray(mesh.vertices, np.float32)))
    params["faces"] = dr.ravel(mi.TensorXu(np.asarray(mesh.faces, np.uint32)))
    params.update()
    return m, _bsdf(material)


class MitsubaBackend:
    """Renders SceneSpecs with Mitsuba; one instance per worker process."""

    name = "mitsuba"

    def __init__(self, model: TargetModel, quality: str = "default", threads: int | None = None) -> None:
        self.variant = select_variant()
        if threads is not None:
            dr.set_thread_count(threads)
        self.model = model
        self.spp = QUALITY_SPP[quality]

    def close(self) -> None:
        pass

    def _shape_dicts(self, spec: SceneSpec) -> tuple[list[dict], list[dict]]:
        """Mitsuba shape dicts for the target parts and for the props (both in the camera frame)."""
        T = spec.target.matrix
        target, props = [], []
        for k, (material, mesh) in enumerate(self.model.parts):
            m = mesh.copy()
            m.apply_transform(T)
            shape, bsdf = _mesh(f"target{k}", m, material)
            target.append({"shape": shape, "bsdf": bsdf})
        for k, prop in enumerate(spec.props):
            shape, bsdf = _mesh(f"prop{k}", prop_mesh(prop), prop.material)
            props.append({"shape": shape, "bsdf": bsdf})
        return target, props

    def render(self, spec: SceneSpec) -> Buffers:
        target, props = self._shape_dicts(spec)
        geo_target = self._geometry_scene(target)
        geo_all = self._geometry_scene(target + props)
        geo_props = self._geometry_scene(props) if props else None

        W, H = spec.camera.width, spec.camera.height
        rays_cam = _pixel_rays(spec.camera.K_mat, W, H)
        t_all, idx_all, normal = _cast(geo_all, [s["shape"] for s in target + props], rays_cam)
        t_tgt, _, _ = _cast(geo_target, [], rays_cam)
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

        rgb = self._shade(spec, target + props)
        return Buffers(
            rgb=rgb,
            depth=depth,
            instance=instance.reshape(H, W),
            target_depth=target_depth,
            normal=normal.reshape(H, W, 3).astype(np.float32),
            sun_blocked=sun_blocked.reshape(H, W),
        )

    @staticmethod
    def _geometry_scene(shapes: list[dict]) -> mi.Scene:
        d = {"type": "scene"}
        for k, s in enumerate(shapes):
            d[f"s{k:03d}"] = s["shape"]
        return mi.load_dict(d)

    def _shade(self, spec: SceneSpec, shapes: list[dict]) -> np.ndarray:
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
                "near_clip": 1e-3,
                "far_clip": 1e4,
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
                "irradiance": {"type": "rgb", "value": [0.8 * irradiance, 0.9 * irradiance, irradiance]},
            }
        for k, s in enumerate(shapes):
            d[f"s{k:03d}"] = s["shape"]
        scene = mi.load_dict(d)
        seed = (spec.seed * 1_000_003 + spec.index) % (2**31)
        img = np.asarray(mi.render(scene, seed=seed), dtype=np.float32)
        fg, alpha = img[..., :3], img[..., 3:4]
        composite = fg + (1.0 - np.clip(alpha, 0, 1)) * background_image(spec)
        return linear_to_srgb8(composite)


def _pixel_rays(K: np.ndarray, W: int, H: int) -> np.ndarray:
    """Unit ray directions through every pixel centre, camera frame, row-major (H*W x 3)."""
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    d = np.stack([u.ravel(), v.ravel(), np.ones(H * W)], 1) @ np.linalg.inv(K).T
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _cast(scene: mi.Scene, shapes: list, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ray length, index of the hit shape in `shapes` (-1 = miss) and geometric normal, rays from origin."""
    o = mi.Point3f(0.0, 0.0, 0.0)
    ray = mi.Ray3f(o, mi.Vector3f(dirs[:, 0], dirs[:, 1], dirs[:, 2]))
    si = scene.ray_intersect(ray)
    valid = np.asarray(si.is_valid())
    t = np.where(valid, np.asarray(si.t, np.float64), np.inf)
    idx = np.full(len(dirs), -1, np.int64)
    for k, shape in enumerate(shapes):  # scene.shapes() is not in insertion order: compare pointers
        idx[np.asarray(si.shape == mi.ShapePtr(shape)) & valid] = k
    n = np.stack([np.asarray(si.n.x), np.asarray(si.n.y), np.asarray(si.n.z)], 1).astype(np.float64)
    return t, idx, np.where(valid[:, None], n, 0.0)


def _occluded(scene: mi.Scene, origins: np.ndarray, direction: np.ndarray) -> np.ndarray:
    if len(origins) == 0:
        return np.zeros(0, bool)
    ray = mi.Ray3f(
        mi.Point3f(origins[:, 0], origins[:, 1], origins[:, 2]),
        mi.Vector3f(*[np.full(len(origins), float(x)) for x in direction]),
    )
    return np.asarray(scene.ray_test(ray), bool)
