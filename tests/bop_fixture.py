"""A BOP dataset that scgen did not write: primitive objects occluding each other, no masks or xyz maps.

`build_bop_dataset(root)` writes the plain BOP layout (camera.json; models in mm with vertex normals and
a models_info.json with symmetries; per scene scene_gt.json, scene_camera.json and one RGB image per
im_id) and nothing more, for `scgen annotate` and for posenet runs on its result. The RGB images and
`first_hits` come from trimesh's own ray caster, independent of the Mitsuba one that annotate uses.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import trimesh
from scipy.spatial.distance import pdist
from trimesh.ray.ray_triangle import RayMeshIntersector

from scgen.io import bop
from scgen.scenes.geometry import random_rotation

SPLIT = "test"
SIZE = (160, 120)  # width, height
FOCAL = 200.0
# scene_id -> im_id -> [(obj_id, t in mm)]: BOP numbering (scenes from 1, im_ids not consecutive), objects
# 35-50 mm apart side by side and 60-100 mm apart in depth so that they overlap; obj 1 twice in image 7,
# obj 5 of image 12 cut by the right border.
SCENES: dict[int, dict[int, list[tuple[int, tuple[float, float, float]]]]] = {
    1: {
        3: [(1, (-25.0, 5.0, 480.0)), (5, (10.0, -5.0, 560.0)), (7, (40.0, 10.0, 640.0))],
        7: [(5, (-30.0, 0.0, 520.0)), (7, (0.0, 10.0, 470.0)), (1, (35.0, -10.0, 600.0)),
            (1, (-60.0, -40.0, 700.0))],
        12: [(7, (-20.0, 0.0, 500.0)), (1, (20.0, 10.0, 580.0)), (5, (175.0, 0.0, 520.0))],
    },
    2: {4: [(1, (0.0, 0.0, 450.0)), (5, (-15.0, 20.0, 530.0)), (7, (30.0, -15.0, 600.0))]},
}  # fmt: skip
COLOURS = {1: (200, 80, 60), 5: (60, 160, 220), 7: (230, 200, 70)}  # RGB per obj_id
FLIP_X, FLIP_Y, FLIP_Z = (np.diag([1.0, -1.0, -1.0, 1.0]), np.diag([-1.0, 1.0, -1.0, 1.0]),
                          np.diag([-1.0, -1.0, 1.0, 1.0]))  # fmt: skip


def object_meshes() -> dict[int, trimesh.Trimesh]:
    """obj_id -> mesh in mm: 1 a box, 5 a cylinder (symmetric about z), 7 a box with an off-centre bump."""
    bump = trimesh.creation.box(extents=(20.0, 20.0, 16.0))
    bump.apply_translation((18.0, 10.0, 28.0))  # on the top face (z = 20) of the 70 x 50 x 40 box
    return {
        1: trimesh.creation.box(extents=(90.0, 60.0, 40.0)),
        5: trimesh.creation.cylinder(radius=25.0, height=80.0, sections=48),
        7: trimesh.util.concatenate([trimesh.creation.box(extents=(70.0, 50.0, 40.0)), bump]),
    }


def models_info(meshes: dict[int, trimesh.Trimesh]) -> dict[str, dict]:
    """models_info.json content: BOP's box entry plus symmetries (box: three half turns; cylinder: z)."""
    info = {}
    for obj_id, mesh in meshes.items():
        diameter = float(pdist(mesh.convex_hull.vertices).max())
        info[str(obj_id)] = bop.models_info_entry(mesh.bounds / bop.MM_PER_M, diameter / bop.MM_PER_M)
    info["1"]["symmetries_discrete"] = [list(T.reshape(16)) for T in (FLIP_X, FLIP_Y, FLIP_Z)]
    info["5"]["symmetries_discrete"] = [list(FLIP_X.reshape(16))]
    info["5"]["symmetries_continuous"] = [{"axis": [0.0, 0.0, 1.0], "offset": [0.0, 0.0, 0.0]}]
    return info


def camera_K(im_id: int) -> np.ndarray:
    """Per-image intrinsics: the principal point moves by a quarter pixel between images."""
    cx = (SIZE[0] - 1) / 2 + 0.25 * (im_id % 3)
    cy = (SIZE[1] - 1) / 2 - 0.25 * (im_id % 2)
    return np.array([[FOCAL, 0.0, cx], [0.0, FOCAL, cy], [0.0, 0.0, 1.0]])


def scene_gt(scene_id: int) -> dict[str, list[dict]]:
    """scene_gt.json content of one scene: random rotations (seeded by scene and image), fixed positions."""
    out = {}
    for im_id, objects in SCENES[scene_id].items():
        rng = np.random.default_rng(1000 * scene_id + im_id)
        out[str(im_id)] = [bop.gt_entry(random_rotation(rng), np.asarray(t) / bop.MM_PER_M, obj_id)
                           for obj_id, t in objects]  # fmt: skip
    return out


def first_hits(gt: list[dict], K: np.ndarray, meshes: dict[int, trimesh.Trimesh]) -> tuple[np.ndarray, ...]:
    """Per pixel: the instance its centre's ray hits first (-1: none), the hit face's normal, the ray."""
    placed = []
    for entry in gt:
        m = meshes[entry["obj_id"]].copy()
        R, t = bop.gt_pose(entry)
        m.vertices = m.vertices @ R.T + t * bop.MM_PER_M
        placed.append(m)
    scene = trimesh.util.concatenate(placed)
    owner = np.repeat(np.arange(len(placed)), [len(m.faces) for m in placed])
    v, u = np.mgrid[0 : SIZE[1], 0 : SIZE[0]].astype(np.float64)
    rays = np.stack([u, v, np.ones_like(u)], -1).reshape(-1, 3) @ np.linalg.inv(K).T
    face = RayMeshIntersector(scene).intersects_first(np.zeros_like(rays), rays)
    hit = face >= 0
    index = np.where(hit, owner[face], -1)
    normals = np.where(hit[:, None], scene.face_normals[face], 0.0)
    shape = (SIZE[1], SIZE[0])
    return index.reshape(shape), normals.reshape(*shape, 3), rays.reshape(*shape, 3)


def render_rgb(gt: list[dict], K: np.ndarray, meshes: dict[int, trimesh.Trimesh]) -> np.ndarray:
    """Flat colours, Lambert-shaded (light at the camera), on a dark grey background: H x W x 3 RGB."""
    index, normals, rays = first_hits(gt, K, meshes)
    rays = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
    shade = 0.3 + 0.7 * np.abs(np.sum(normals * rays, axis=-1))
    colours = np.array([COLOURS[e["obj_id"]] for e in gt] + [(40, 40, 40)], np.float64)
    return np.clip(colours[index] * np.where(index >= 0, shade, 1.0)[..., None], 0, 255).astype(np.uint8)


def build_bop_dataset(root: Path) -> Path:
    """Write the dataset under `root` (created) and return `root`."""
    meshes = object_meshes()
    (root / bop.MODELS_DIR).mkdir(parents=True)
    for obj_id, mesh in meshes.items():
        data = trimesh.exchange.ply.export_ply(mesh, encoding="ascii", vertex_normal=True)
        (root / bop.MODELS_DIR / bop.model_file(obj_id)).write_bytes(data)
    _write_json(root / bop.MODELS_DIR / bop.MODELS_INFO_FILE, models_info(meshes))
    K0 = camera_K(0)
    camera = {"cx": K0[0, 2], "cy": K0[1, 2], "fx": FOCAL, "fy": FOCAL, "width": SIZE[0], "height": SIZE[1],
              "depth_scale": 1.0}  # fmt: skip
    _write_json(root / bop.CAMERA_FILE, camera)
    for scene_id in SCENES:
        scene = bop.scene_dir(root, SPLIT, scene_id)
        (scene / "rgb").mkdir(parents=True)
        gt = scene_gt(scene_id)
        cams = {im: {"cam_K": list(camera_K(int(im)).reshape(9)), "depth_scale": 1.0} for im in gt}
        _write_json(bop.scene_file(scene, "scene_gt"), gt)
        _write_json(bop.scene_file(scene, "scene_camera"), cams)
        for im, entries in gt.items():
            rgb = render_rgb(entries, camera_K(int(im)), meshes)
            cv2.imwrite(str(bop.rgb_path(scene, int(im))), rgb[..., ::-1])
    return root


def _write_json(path: Path, content: dict) -> None:
    path.write_text(json.dumps(content, indent=2))
