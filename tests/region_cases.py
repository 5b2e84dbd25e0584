"""The region render's test cases, shared by the Blender and Mitsuba region tests: specs whose objects
reach the frame's edge (a target partly out of view, an occluder across the frame) or whose camera stage
spreads glare over it, and the image error over the rendered objects."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from scgen.scenes.spec import Pose, SunSpec

OCCLUDED = {"occluders": {"group_probs": {"none": 0.0, "slight": 0.0, "moderate": 1.0, "heavy": 0.0}}}


def partly_out_of_view(spec):
    """The target moved so that its centre projects onto the frame's left edge."""
    t = spec.target.t_vec.copy()
    K = spec.camera.K_mat
    t[0] = -K[0, 2] * t[2] / K[0, 0]
    return replace(spec, target=Pose(spec.target.R, tuple(t)))


def occluder_across_the_frame(spec):
    """The first prop made a truss along the image's rows, so near the camera that it spans the frame's
    width (a band: not the whole frame)."""
    K, width = spec.camera.K_mat, spec.camera.width
    length = 0.2
    z = 0.75 * length * K[0, 0] / width  # its length projects onto 4/3 of the width
    identity = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    pose = Pose(identity, (0.0, 0.0, z))
    truss = replace(spec.props[0], shape="truss", size=(length, 0.03, 0.03), pose=pose)
    return replace(spec, props=(truss, *spec.props[1:]))


def objects_apart(spec):
    """The target's centre moved to the frame's upper left sixth and the first prop made a small truss in
    its lower right, the other props dropped: the two cover disjoint regions with empty pixels between."""
    K, width, height = spec.camera.K_mat, spec.camera.width, spec.camera.height
    z = spec.target.t_vec[2]
    at = lambda u, v: tuple(z * np.linalg.solve(K, [u, v, 1.0]))  # noqa: E731  the point at depth z on pixel (u, v)
    target = Pose(spec.target.R, at(width / 6, height / 6))
    identity = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    length = 0.05 * width * z / K[0, 0]  # a twentieth of the width
    truss = replace(spec.props[0], shape="truss", size=(length, length / 5, length / 5),
                    pose=Pose(identity, at(5 * width / 6, 5 * height / 6)))  # fmt: skip
    return replace(spec, target=target, props=(truss,))


def sun_in_view(spec):
    """The sun just off the optical axis: its disc, ghosts and veiling glare over the whole image."""
    s = np.array([0.05, -0.03, 1.0])
    return replace(spec, sun=SunSpec(tuple(s / np.linalg.norm(s)), "normal", 1361.0))


CASES = {
    "default": lambda spec: spec,
    "partly out of view": partly_out_of_view,
    "occluder across the frame": occluder_across_the_frame,
    "sun glare": sun_in_view,
}
APART = {"objects apart": objects_apart}  # several regions: Blender traces each (Mitsuba one window)


def rms_over_objects(a: np.ndarray, b: np.ndarray, instance: np.ndarray) -> float:
    on = instance > 0
    return float(np.sqrt(np.mean((a.astype(np.float64) - b.astype(np.float64))[on] ** 2)))
