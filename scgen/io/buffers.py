"""What a renderer returns for one scene: per-pixel buffers and the instance-id convention.

Renderers produce Buffers, annotate and the writer consume them: the one scgen.render module that
annotation and the writer import.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BACKGROUND_ID = 0
TARGET_ID = 1  # then the other labelled objects (SceneSpec.objects), then the props (SceneSpec.props)
# What one sample holds at once, per pixel, at the least: the Buffers below (rgb 3, depth 4, instance 4,
# target_depth 4, normal 12, sun_blocked 1 bytes), the linear radiance the camera stage starts from (12)
# and the labels annotate makes of them (the xyz map 12, the two masks 2). A renderer holds more (its
# own film and passes), so a frame this bound does not fit in memory cannot be rendered.
SAMPLE_BYTES_PER_PIXEL = 3 + 4 + 4 + 4 + 12 + 1 + 12 + 12 + 2


def object_instance_id(j: int) -> int:
    """The instance id of SceneSpec.objects[j], the labelled object of scene_gt entry 1 + j."""
    return TARGET_ID + 1 + j


def prop_instance_id(objects: int, k: int) -> int:
    """The instance id of SceneSpec.props[k] in a scene of `objects` labelled objects beside the target
    (2 + k with none, as always)."""
    return TARGET_ID + 1 + objects + k


@dataclass(frozen=True)
class CameraRecord:
    """What the camera stage decided for one image: the exposure it used (base + shift, EV), whether the
    sun flared, and the share of pixel values at the ADC's top code (over-exposure)."""

    exposure_ev: float
    flare: bool
    saturated: float


@dataclass
class Buffers:
    """Per-pixel renderer output, all H x W, OpenCV pixel-centre convention.

    depth / target_depth: z along the optical axis in metres, 0 where nothing is hit.
    instance: BACKGROUND_ID, TARGET_ID, object_instance_id(j) or prop_instance_id(len(objects), k).
    normal: camera-frame unit normal facing the camera on the target's pixels, zeros elsewhere (the shadow
    label reads it there alone, so the Blender backend's aux render traces only the target's region).
    sun_blocked: the ray from the visible surface towards the sun hits a non-target object.
    """

    rgb: np.ndarray  # the recorded image (the camera stage's): uint8/uint16, H x W x 3 or H x W (mono)
    depth: np.ndarray  # float32
    instance: np.ndarray  # int32
    target_depth: np.ndarray  # float32, the target rendered alone (for the full mask)
    normal: np.ndarray  # float32 H x W x 3
    sun_blocked: np.ndarray  # bool
    camera: CameraRecord | None = None  # set with rgb by the camera stage
    # each of SceneSpec.objects rendered alone, as target_depth (empty for a target alone)
    objects_depth: tuple[np.ndarray, ...] = ()
