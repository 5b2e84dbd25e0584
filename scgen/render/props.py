"""Procedural meshes for non-target objects, identical for every backend (so labels agree)."""

from __future__ import annotations

import numpy as np
import trimesh

from scgen.scenes.spec import PropSpec


def prop_mesh(prop: PropSpec) -> trimesh.Trimesh:
    """The prop's triangle mesh in the camera frame."""
    mesh = _local_mesh(prop.shape, np.asarray(prop.size), np.random.default_rng(prop.seed))
    mesh.apply_transform(prop.pose.matrix)
    return mesh


def _local_mesh(shape: str, size: np.ndarray, rng: np.random.Generator) -> trimesh.Trimesh:
    if shape in ("panel", "box"):
        return trimesh.creation.box(extents=size)
    if shape in ("rod", "arm"):
        mesh = trimesh.creation.cylinder(radius=0.5 * min(size[1], size[2]), height=size[0], sections=20)
        mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
        if shape == "arm":  # a robotic-arm link: a rod with a joint housing at each end
            joints = []
            for end in (-0.5, 0.5):
                joint = trimesh.creation.cylinder(radius=0.9 * size[1], height=1.2 * size[1], sections=20)
                joint.apply_translation([end * size[0], 0, 0])
                joints.append(joint)
            mesh = trimesh.util.concatenate([mesh, *joints])
        return mesh
    if shape == "debris":  # an irregular fragment: a jittered convex hull
        pts = rng.uniform(-0.5, 0.5, size=(24, 3)) * size
        return trimesh.convex.convex_hull(pts)
    if shape == "truss":  # a square truss segment: four longerons and cross members
        members = []
        h = 0.5 * size[1]
        r = 0.04 * size[1]
        for y, z in ((-h, -h), (-h, h), (h, -h), (h, h)):
            members.append(
                trimesh.creation.cylinder(radius=r, segment=[[-size[0] / 2, y, z], [size[0] / 2, y, z]])
            )
        for x in np.linspace(-size[0] / 2, size[0] / 2, 4):
            members.append(trimesh.creation.cylinder(radius=r, segment=[[x, -h, -h], [x, h, h]]))
            members.append(trimesh.creation.cylinder(radius=r, segment=[[x, -h, h], [x, h, -h]]))
        return trimesh.util.concatenate(members)
    raise ValueError(f"unknown prop shape {shape!r}")
