"""The labelled objects beside the target (SceneSpec.objects), as every backend draws and labels them.

Each is drawn like a prop, part by part in its classes' nominal materials (the sample's finish is the
target's), so it occludes the target and shades it as a prop does and every pass that holds the props
holds it. Its full mask, the object alone, is an exact ray cast through every pixel centre it may cover
(scgen.render.mitsuba.raycast, as `scgen annotate` casts instances), the same in both backends.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import trimesh

from scgen.io.bop import TARGET_OBJ_ID
from scgen.io.buffers import object_instance_id
from scgen.scenes.model import TargetModel
from scgen.scenes.projection import projection_box
from scgen.scenes.spec import CameraSpec, Pose, SceneSpec


@dataclass(frozen=True)
class ObjectPart:
    """One material part of a labelled object: its mesh in the model frame, placed by `pose`."""

    instance: int  # its object's instance id (scgen.io.buffers.object_instance_id)
    obj_id: int
    part: int  # its index in the model's parts
    material: str
    mesh: trimesh.Trimesh
    pose: Pose


def object_parts(spec: SceneSpec, models: Mapping[int, TargetModel]) -> list[ObjectPart]:
    """Every part of every labelled object of `spec` beside the target, object by object."""
    return [ObjectPart(object_instance_id(j), obj.obj_id, k, material, mesh, obj.pose)
            for j, obj in enumerate(spec.objects)
            for k, (material, mesh) in enumerate(models[obj.obj_id].parts)]  # fmt: skip


def object_hulls(spec: SceneSpec, hulls: Mapping[int, np.ndarray]) -> list[np.ndarray]:
    """Each labelled object's convex hull vertices (`hulls` by obj_id, model frame) in the camera frame."""
    return [hulls[obj.obj_id] @ obj.pose.R_mat.T + obj.pose.t_vec for obj in spec.objects]


def with_target(model: TargetModel, models: Mapping[int, TargetModel] | None) -> dict[int, TargetModel]:
    """A backend's models by obj_id: `models` (None: none but the target) with the target's, `model`."""
    return {**(models or {}), TARGET_OBJ_ID: model}


def model_hulls(models: Mapping[int, TargetModel]) -> dict[int, np.ndarray]:
    """The vertices of each model's convex hull (model frame), by obj_id."""
    return {k: np.asarray(m.mesh.convex_hull.vertices, np.float64) for k, m in models.items()}


def objects_alone_depth(spec: SceneSpec, models: Mapping[int, TargetModel]) -> tuple[np.ndarray, ...]:
    """Each labelled object beside the target rendered alone: z depth (metres, float32, 0 where it is not
    hit) through every pixel centre of the image, one exact ray cast over the pixels it may cover."""
    if not spec.objects:
        return ()
    from scgen.render.mitsuba import raycast

    raycast.start()
    cam = spec.camera
    out = []
    for obj in spec.objects:
        model = models[obj.obj_id]
        vertices, faces = np.asarray(model.mesh.vertices), np.asarray(model.mesh.faces)
        R, t = obj.pose.R_mat, obj.pose.t_vec
        depth = np.zeros((cam.height, cam.width), np.float32)
        box = image_box(vertices @ R.T + t, cam)
        if box is not None:
            x0, y0, x1, y1 = box
            shape = raycast.place_mesh("alone", vertices, faces, R, t)
            _, d = raycast.cast([shape], cam, (x0, y0, x1 - x0, y1 - y0))
            depth[y0:y1, x0:x1] = d
        out.append(depth)
    return tuple(out)


def image_box(points: np.ndarray, cam: CameraSpec) -> tuple[int, int, int, int] | None:
    """Columns [x0, x1) and rows [y0, y1) of the image holding every pixel whose ray may meet the convex
    hull of camera-frame `points`: with a pinhole, around their projections (projection_box); through a
    lens, whose images of straight edges bend, the pixels whose undistorted rays (CameraSpec.pixel_rays)
    fall in the box of the points' pinhole images. The whole image where a point is behind the camera;
    None where no pixel is in reach."""
    W, H = cam.width, cam.height
    if not (points[:, 2] > 0).all():
        return 0, 0, W, H
    if cam.pinhole:
        box = projection_box(points, np.eye(3), np.zeros(3), cam)
        if box is None:
            return None
        x0, y0, x1, y1 = max(box[0], 0), max(box[1], 0), min(box[0] + box[2], W), min(box[1] + box[3], H)
        return (x0, y0, x1, y1) if x0 < x1 and y0 < y1 else None
    xy = points[:, :2] / points[:, 2:3]
    rays = cam.pixel_rays()
    inside = ((rays[..., :2] >= xy.min(axis=0)) & (rays[..., :2] <= xy.max(axis=0))).all(axis=-1)
    ys, xs = np.nonzero(inside)
    if len(xs) == 0:
        return None
    return int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1
