"""Mitsuba 3 backend: fast CPU renders for tests and an independent cross-check of Blender.

RGB comes from Mitsuba's path tracer; the geometric passes (depth, instance ids, normals,
the target-alone depth, shadow rays) come from exact ray casts through pixel centres, so no
filtered or jittered sample ever blends two surfaces at an edge.

Per sample one scene holds the target (one mesh per material class) and the props, for the path tracer
and the ray casts alike. Dr.Jit traces every live shape, BSDF and light into each kernel and compiles a
kernel anew for each new set of them or of the constants they bake in (LLVM: about 0.3 s at any image
size), so that set is kept steady from sample to sample: see _steady_shapes, _steady_light_bounds and
mitsuba_materials.TargetFinishes.
"""

from __future__ import annotations

from dataclasses import replace

import drjit as dr
import mitsuba as mi
import numpy as np
from trimesh.transformations import transform_points

from scgen.render.backgrounds import background_image
from scgen.render.buffers import BACKGROUND_ID, TARGET_ID, Buffers
from scgen.render.camera import record_image, render_camera
from scgen.render.conventions import CLIP_END_M, CLIP_START_M, EARTHSHINE_COLOUR, check_quality, render_seed
from scgen.render.lighting import earth_albedo_light, sun_render_irradiance
from scgen.render.mitsuba_llvm import mitsuba_setup
from scgen.render.mitsuba_materials import TargetFinishes, box_uv, build_bsdfs, texture_scale
from scgen.render.props import prop_mesh
from scgen.scenes.model import TargetModel
from scgen.scenes.spec import SceneSpec

QUALITY_SPP = {"draft": 4, "default": 16, "high": 64}
GUARD_M = 1e4  # half the span of the guard triangle (see MitsubaBackend.__init__)
MIN_PROP_SLOTS = 12  # live meshes kept for props from the start (the default config draws at most 9)


def select_variant() -> str:
    """Set the variant mitsuba_llvm chose for this process (llvm_ad_rgb when its libLLVM renders, else
    scalar_rgb), unless one is set already; returns the variant in use."""
    if mi.variant() is None:
        mi.set_variant(mitsuba_setup().variant)
    return mi.variant()


def _mesh(name: str, corners: np.ndarray, uv: np.ndarray, bsdf: mi.BSDF) -> mi.Mesh:
    """A Mitsuba mesh of unwelded triangles: `corners` (3F x 3) and `uv` (3F x 2) hold three per face, in
    face order, as box_uv lays them out."""
    props = mi.Properties()
    props["bsdf"] = bsdf
    n = len(corners)
    m = mi.Mesh(name, n, n // 3, props=props, has_vertex_normals=False, has_vertex_texcoords=True)
    params = mi.traverse(m)
    params["vertex_positions"] = dr.ravel(mi.TensorXf(corners.astype(np.float32)))
    params["faces"] = dr.ravel(mi.TensorXu(np.arange(n, dtype=np.uint32)))
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
        self._classes: dict[str, list[int]] = {}  # material class -> its parts, one target mesh each
        for k, (material, _) in enumerate(model.parts):
            self._classes.setdefault(material, []).append(k)
        self._uv: dict[tuple[int, str], np.ndarray] = {}  # (part, class rendered) -> the part's UVs
        self._finishes = TargetFinishes()
        self._reach = 1.01 * float(np.linalg.norm(model.mesh.vertices, axis=1).max())  # target's radius
        self._most_props = MIN_PROP_SLOTS  # the most props a sample had so far, at least this
        self._spares: list[mi.Mesh] = []  # see _steady_shapes
        # one triangle of no area, never hit, whose box spans 20 km: beside it Embree finds no spatial
        # split worth making, and builds the target's BVH in 8 ms instead of 19 (labels are the same)
        far = GUARD_M * np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, -1.0], [1.0, 1.0, -1.0]])
        self._guard = _mesh("guard", far, np.zeros((3, 2)), self.bsdfs["white_paint"])

    def close(self) -> None:
        pass

    def _shapes(self, spec: SceneSpec, shaded: bool = True) -> tuple[list[mi.Mesh], list[mi.Mesh]]:
        """Mitsuba meshes in the camera frame: the target's, one per material class (its parts, in model
        order), and one per prop. `shaded`: with the sample's finish (else the nominal BSDFs)."""
        T = spec.target.matrix
        finish = {cls: f for cls, f in spec.finish.items() if cls in self._classes} if shaded else {}
        bsdfs = {**self.bsdfs, **self._finishes.bsdfs(finish)}
        target = []
        for cls, parts in self._classes.items():
            drawn = spec.finish[cls]["material"] if cls in spec.finish else cls
            corners = [transform_points(mesh.vertices, T)[mesh.faces].reshape(-1, 3)
                       for mesh in (self.model.parts[k][1] for k in parts)]  # fmt: skip
            uv = np.concatenate([self._part_uv(k, drawn) for k in parts])
            target.append(_mesh(f"target_{cls}", np.concatenate(corners), uv, bsdfs[cls]))
        props = []
        for k, prop in enumerate(spec.props):
            m = prop_mesh(prop)
            local = (np.asarray(m.vertices) - prop.pose.t_vec) @ prop.pose.R_mat  # UVs stick to the prop
            uv = box_uv(local, np.asarray(m.faces), texture_scale(prop.material, max(prop.size)))
            corners = np.asarray(m.vertices)[np.asarray(m.faces)].reshape(-1, 3)
            props.append(_mesh(f"prop{k}", corners, uv, self.bsdfs[prop.material]))
        return target, props

    def _part_uv(self, k: int, material: str) -> np.ndarray:
        """Target part k's UVs, scaled for the material class it is rendered with."""
        if (k, material) not in self._uv:
            mesh = self.model.parts[k][1]
            scale = texture_scale(material, self.model.diameter)
            self._uv[k, material] = box_uv(np.asarray(mesh.vertices), np.asarray(mesh.faces), scale)
        return self._uv[k, material]

    def render(self, spec: SceneSpec) -> Buffers:
        self._steady_shapes(len(spec.props))
        target, props = self._shapes(spec)
        scene = self._scene(spec, target + props)
        buffers = self._passes(spec, scene, target, props)
        buffers.rgb, buffers.camera = record_image(spec, self._shade(spec, scene), buffers.instance)
        return buffers

    def render_geometry(self, spec: SceneSpec) -> Buffers:
        """Only the exact geometric passes (RGB left black): labels at a fraction of the cost."""
        self._steady_shapes(len(spec.props))
        target, props = self._shapes(spec, shaded=False)
        return self._passes(spec, self._scene_of(target + props), target, props)

    def _steady_shapes(self, n_props: int) -> None:
        """Keep the count of live shapes at the target's plus the most props seen (MIN_PROP_SLOTS at
        least), with spare meshes in no scene: Dr.Jit lays out every live shape's data in each kernel that
        calls into shapes (ray casts, the path tracer), so each new count of props compiled new kernels.
        A spare adds about 0.13 ms to a render."""
        self._most_props = max(self._most_props, n_props)
        del self._spares[self._most_props - n_props :]
        while len(self._spares) < self._most_props - n_props:
            self._spares.append(_mesh("spare", np.zeros((3, 3)), np.zeros((3, 2)), self.bsdfs["white_paint"]))

    def _passes(
        self, spec: SceneSpec, scene: mi.Scene, target: list[mi.Mesh], props: list[mi.Mesh]
    ) -> Buffers:
        """The exact geometric passes of `scene` (holding `target` and `props`): one ray per pixel centre.

        The target-alone depth equals the depth wherever the target is hit first; only the rays that hit
        a prop no farther than the target's bounding sphere reaches are cast again, through the target alone.
        """
        W, H = spec.camera.width, spec.camera.height
        rays_cam = spec.camera.pixel_directions().reshape(-1, 3)
        t_all, idx_all, normal = cast_rays(scene, target + props, rays_cam)
        n_target = len(target)
        hit = idx_all >= 0
        on_target = hit & (idx_all < n_target)
        on_prop = hit & ~on_target
        t_tgt = np.where(on_target, t_all, np.inf)
        behind = on_prop & self._may_reach_target(spec, rays_cam, t_all)
        if behind.any():
            t_tgt[behind] = cast_rays(self._scene_of(target), [], rays_cam[behind])[0]
        z_scale = rays_cam[:, 2]
        depth = np.where(np.isfinite(t_all), t_all * z_scale, 0.0).reshape(H, W).astype(np.float32)
        target_depth = np.where(np.isfinite(t_tgt), t_tgt * z_scale, 0.0).reshape(H, W).astype(np.float32)
        instance = np.full(H * W, BACKGROUND_ID, np.int32)
        instance[on_target] = TARGET_ID
        instance[on_prop] = 2 + (idx_all[on_prop] - n_target)
        normal = np.where((np.sum(normal * rays_cam, axis=1) > 0)[:, None], -normal, normal)

        sun = np.asarray(spec.sun.direction, np.float64)
        sun_blocked = np.zeros(H * W, bool)
        if props and on_target.any():
            origins = rays_cam[on_target] * t_all[on_target, None] + 1e-4 * normal[on_target]
            sun_blocked[on_target] = _occluded(self._scene_of(props), origins, sun)

        return Buffers(
            rgb=np.zeros((H, W, 3), np.uint8),
            depth=depth,
            instance=instance.reshape(H, W),
            target_depth=target_depth,
            normal=normal.reshape(H, W, 3).astype(np.float32),
            sun_blocked=sun_blocked.reshape(H, W),
        )

    def _scene_of(self, shapes: list[mi.Mesh]) -> mi.Scene:
        """A scene of these shapes alone (and the guard), for ray casts."""
        shapes = [*shapes, self._guard]
        return mi.load_dict({"type": "scene", **{f"s{k:03d}": s for k, s in enumerate(shapes)}})

    def _may_reach_target(self, spec: SceneSpec, rays: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Whether each ray (unit directions from the camera) meets the target's bounding sphere (about
        its origin, 1 % wider) anywhere beyond distance t."""
        centre = np.asarray(spec.target.t_vec, np.float64)
        along = rays @ centre
        gap2 = centre @ centre - along**2  # squared distance from the sphere's centre to the ray's line
        return (gap2 <= self._reach**2) & (t <= along + np.sqrt(np.maximum(self._reach**2 - gap2, 0.0)))

    def _scene(self, spec: SceneSpec, shapes: list[mi.Mesh]) -> mi.Scene:
        """The path tracer's scene: `shapes`, the sun (and earthshine), the render camera
        (scgen.render.camera.lens) and its film."""
        cam = render_camera(spec.camera)
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
        for k, s in enumerate([*shapes, self._guard]):
            d[f"s{k:03d}"] = s
        scene = mi.load_dict(d)
        _steady_light_bounds(scene, shapes)
        return scene

    def _shade(self, spec: SceneSpec, scene: mi.Scene) -> np.ndarray:
        """The linear composite over the background, on the render camera (scgen.render.camera.lens)."""
        img = np.asarray(mi.render(scene, seed=render_seed(spec)), dtype=np.float32)
        fg, alpha = img[..., :3], img[..., 3:4]
        background = background_image(replace(spec, camera=render_camera(spec.camera)))
        return fg + (1.0 - np.clip(alpha, 0, 1)) * background


def _steady_light_bounds(scene: mi.Scene, shapes: list[mi.Mesh]) -> None:
    """Give the directional lights a bounding sphere about the camera whose radius is the power of two that
    encloses the scene: they keep their scene's sphere as constants of the render kernel, so the scene's
    own sphere compiled a new kernel for every sample."""
    corners = [np.asarray(c) for s in shapes for c in (s.bbox().min, s.bbox().max)]
    extent = float(np.abs(corners).max())
    half = 2.0 ** np.ceil(np.log2(max(extent, CLIP_START_M)))
    cube = {"type": "cube", "to_world": mi.ScalarTransform4f().scale([half] * 3)}
    bounds = mi.load_dict({"type": "scene", "cube": cube})
    for emitter in scene.emitters():
        emitter.set_scene(bounds)


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
