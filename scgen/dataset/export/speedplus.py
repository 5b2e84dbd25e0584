"""SPEED+'s layout, as its reference pipelines (speedplusbaseline, SPNv2) read it.

    OUT/camera.json                  cameraMatrix, distCoeffs, Nu, Nv, ppx, ppy, fx, fy, ccx, ccy
    OUT/synthetic/images/img{sample_id:06d}.{png|jpg}
    OUT/synthetic/{train,validation,test}.json   [{filename, q_vbs2tango_true, r_Vo2To_vbs_true}]

SPEED+'s client (speedplusbaseline's `project_keypoints`) projects a body point X to the camera frame as
quat2dcm(q)ᵀ X + r, and its quat2dcm(q) is the direction cosine matrix of the camera (VBS) frame to the
body (Tango) frame: Rᵀ of the active rotation R(q). So q is the scalar-first quaternion of BOP's R
(X_cam = R X_model + t) itself and r is t in metres; the body frame is the model frame.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from scgen.dataset.export.output import ExportFormat, place_image
from scgen.dataset.export.source import Sample, Source
from scgen.dataset.layout import dumps
from scgen.errors import ScgenError
from scgen.scenes.geometry import matrix_to_quat

DOMAIN = "synthetic"  # SPEED+'s folder of one image domain: {dataroot}/{domain}/{images,*.json}
LABEL_FILES = {"train": "train.json", "val": "validation.json", "test": "test.json"}
# scgen's camera exists in pixels only; SPEED+ also states the sensor's pixel pitch (m) and the focal
# length in metres. We write SPEED+'s own pitch, 5.86 µm, as a nominal value and the metric focal length
# that gives the same K (fx_m / ppx = fx_px): nothing in the images depends on them.
NOMINAL_PIXEL_PITCH_M = 5.86e-6


def pose_label(R: np.ndarray, t: np.ndarray) -> tuple[list[float], list[float]]:
    """(q_vbs2tango, r_Vo2To_vbs) of a BOP pose: the scalar-first quaternion of R, and t in metres."""
    return [float(x) for x in matrix_to_quat(R)], [float(x) for x in t]


def image_name(sample: Sample) -> str:
    return f"img{sample.sample_id:06d}{sample.image.suffix}"


def label(sample: Sample) -> dict[str, Any]:
    q, r = pose_label(sample.R, sample.t)
    return {"filename": image_name(sample), "q_vbs2tango_true": q, "r_Vo2To_vbs_true": r}


def camera(source: Source) -> dict[str, Any]:
    """camera.json: the dataset's one camera (SPEED+ has one per dataset)."""
    first = source.samples[0]
    for s in source.samples:
        if not (np.array_equal(s.K, first.K) and np.array_equal(s.dist, first.dist)):
            raise ScgenError(f"SPEED+ holds one camera, but sample {s.sample_id}'s cam_K or cam_dist differs "
                             f"from sample {first.sample_id}'s")  # fmt: skip
    K, pitch = first.K, NOMINAL_PIXEL_PITCH_M
    return {"Nu": source.size[0], "Nv": source.size[1], "ppx": pitch, "ppy": pitch,
            "fx": float(K[0, 0]) * pitch, "fy": float(K[1, 1]) * pitch,
            "ccx": float(K[0, 2]), "ccy": float(K[1, 2]),
            "cameraMatrix": K.tolist(), "distCoeffs": first.dist.tolist()}  # fmt: skip


def write(source: Source, out: Path, images: str) -> dict[str, int]:
    """Write the SPEED+ layout into `out`; returns the number of images per label file."""
    (out / "camera.json").write_text(dumps(camera(source)))
    image_dir = out / DOMAIN / "images"
    image_dir.mkdir(parents=True)
    counts = {}
    for split, name in LABEL_FILES.items():
        samples = source.split(split)
        for s in samples:
            place_image(s.image, image_dir / image_name(s), images)
        (out / DOMAIN / name).write_text(dumps([label(s) for s in samples]))
        counts[f"{DOMAIN}/{name}"] = len(samples)
    return counts


FORMAT = ExportFormat(
    name="speedplus",
    summary="SPEED+'s camera.json, images and train/validation/test labels",
    layout="OUT/camera.json, OUT/synthetic/images/, OUT/synthetic/{train,validation,test}.json",
    write=write,
    writes_images=True,
)
