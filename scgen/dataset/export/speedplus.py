"""SPEED+'s layout, as its reference pipelines (speedplusbaseline, SPNv2) read it.

    OUT/camera.json                  cameraMatrix, distCoeffs, Nu, Nv, ppx, ppy, fx, fy, ccx, ccy
    OUT/synthetic/images/img{sample_id:06d}.{png|jpg}
    OUT/synthetic/{train,validation,test}.json   [{filename, q_vbs2tango_true, r_Vo2To_vbs_true}]

A sequence dataset is written as SHIRT (SLAB's rendezvous trajectories, read by the same clients) lays out
a trajectory: one folder per sequence, its label file in time order.

    OUT/camera.json
    OUT/trajectories.json            {train, validation, test: [seq{K:04d}, ...]}: the split, by sequence
    OUT/seq{K:04d}/metadata.json     cam_step (s), num_images, r_pri2cam_pri, q_pri2cam, sequence factors
    OUT/seq{K:04d}/synthetic/images/img{sample_id:06d}.{png|jpg}
    OUT/seq{K:04d}/synthetic/seq{K:04d}.json     [{filename, ...}] as above, frame 0 first

SPEED+'s client (speedplusbaseline's `project_keypoints`) projects a body point X to the camera frame as
quat2dcm(q)ᵀ X + r, and its quat2dcm(q) is the direction cosine matrix of the camera (VBS) frame to the
body (Tango) frame: Rᵀ of the active rotation R(q). So q is the scalar-first quaternion of BOP's R
(X_cam = R X_model + t) itself and r is t in metres; the body frame is the model frame.

The labels are one object's: the target's, or on a dataset with several labelled objects the one chosen
with `scgen export --obj-id` (an object with one instance per image).
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
TRAJECTORY_INDEX = "trajectories.json"  # a sequence export's trajectory folders per split
# SHIRT's servicer-to-camera offset: scgen's camera is the chaser's body frame, so it is the identity
SERVICER_TO_CAMERA = {"r_pri2cam_pri": [0.0, 0.0, 0.0], "q_pri2cam": [1.0, 0.0, 0.0, 0.0]}


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


def trajectory_name(sequence_id: int) -> str:
    return f"seq{sequence_id:04d}"


def trajectories(source: Source) -> dict[int, list[Sample]]:
    """A sequence dataset's frames per sequence id, each in time order; a sequence whose frames are not
    0..frames-1 of one split is refused (`scgen validate` names why)."""
    frames: dict[int, list[Sample]] = {}
    for s in source.samples:
        frames.setdefault(int(s.metadata["sequence_id"]), []).append(s)
    for seq, samples in frames.items():
        samples.sort(key=lambda s: int(s.metadata["frame"]))
        if [int(s.metadata["frame"]) for s in samples] != list(range(len(samples))):
            raise ScgenError(f"sequence {seq}: frames {[s.metadata['frame'] for s in samples]} are not "
                             "0, 1, ... (run `scgen validate`)")  # fmt: skip
        if len({s.split for s in samples}) > 1:
            raise ScgenError(f"sequence {seq}: frames in more than one split (run `scgen validate`)")
    return dict(sorted(frames.items()))


def trajectory_metadata(source: Source, samples: list[Sample]) -> dict[str, Any]:
    """A trajectory's metadata.json: SHIRT's keys (frame step, frame count, servicer-to-camera offset),
    then the sequence's id and factors."""
    assert source.sequence is not None
    row = samples[0].metadata
    return {"cam_step": float(source.sequence["dt_s"]), "num_images": len(samples), **SERVICER_TO_CAMERA,
            "sequence_id": int(row["sequence_id"]), "profile": row["profile"],
            "attitude_mode": row["attitude_mode"], "altitude_km": float(row["altitude_km"])}  # fmt: skip


def write_trajectories(source: Source, out: Path, images: str) -> dict[str, int]:
    """Write a sequence dataset as SHIRT's trajectories into `out` (camera.json written); returns the
    number of images per label file."""
    index: dict[str, list[str]] = {Path(name).stem: [] for name in LABEL_FILES.values()}
    counts = {}
    for seq, samples in trajectories(source).items():
        name = trajectory_name(seq)
        index[Path(LABEL_FILES[samples[0].split]).stem].append(name)
        image_dir = out / name / DOMAIN / "images"
        image_dir.mkdir(parents=True)
        for s in samples:
            place_image(s.image, image_dir / image_name(s), images)
        (out / name / "metadata.json").write_text(dumps(trajectory_metadata(source, samples)))
        (out / name / DOMAIN / f"{name}.json").write_text(dumps([label(s) for s in samples]))
        counts[f"{name}/{DOMAIN}/{name}.json"] = len(samples)
    (out / TRAJECTORY_INDEX).write_text(dumps(index))
    return counts


def write(source: Source, out: Path, images: str) -> dict[str, int]:
    """Write the SPEED+ layout into `out` (SHIRT's for a sequence dataset); returns the number of images
    per label file."""
    (out / "camera.json").write_text(dumps(camera(source)))
    if source.sequence:
        return write_trajectories(source, out, images)
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
    summary="SPEED+'s camera.json, images and train/validation/test labels (SHIRT's trajectories for "
    "a sequence dataset)",
    layout="OUT/camera.json, OUT/synthetic/images/, OUT/synthetic/{train,validation,test}.json; sequences: "
    "OUT/seqK/{metadata.json,synthetic/images/,synthetic/seqK.json}, OUT/trajectories.json",
    write=write,
    writes_images=True,
    one_object=True,
)
