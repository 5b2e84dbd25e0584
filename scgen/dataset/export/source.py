"""A scgen dataset as the exporters read it: one record per sample, from the dataset's own readers.

The dataset is read and checked before the export starts, so bad input is named in one line
(ScgenError) before anything is written.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from tqdm import tqdm

from scgen.dataset.layout import OBJ_ID, TARGET_INSTANCE, Layout, object_names, open_dataset, read_metadata
from scgen.errors import ScgenError
from scgen.io import bop
from scgen.io.image_file import read_image, why_unreadable

if TYPE_CHECKING:
    from scgen.dataset.bop_dataset import BopImage


@dataclass(frozen=True)
class Instance:
    """One scene_gt instance of an image: its object, pose (model to camera, metres) and labels."""

    obj_id: int
    R: np.ndarray
    t: np.ndarray
    mask_visib: Path
    gt_info: dict[str, Any]  # its scene_gt_info.json entry


@dataclass(frozen=True)
class Sample:
    """One rendered image with its target's pose (model to camera, metres), camera and labels; every
    labelled instance (the target first) in `instances`."""

    sample_id: int
    split: str
    image: Path  # the rendered image, in the format it was rendered in
    mask_visib: Path
    R: np.ndarray
    t: np.ndarray
    K: np.ndarray
    dist: np.ndarray  # (5,), zeros for a pinhole camera
    gt_info: dict[str, Any]  # the target's scene_gt_info.json entry
    metadata: dict[str, str]  # the sample's metadata.csv row
    instances: tuple[Instance, ...] = ()  # in scene_gt order

    def of_object(self, obj_id: int) -> Sample:
        """The sample with object `obj_id`'s pose and labels in place of the target's; a one-line
        ScgenError unless the image holds exactly one instance of it."""
        found = [i for i in self.instances if i.obj_id == obj_id]
        if len(found) != 1:
            raise ScgenError(f"sample {self.sample_id} holds {len(found)} instances of obj_id {obj_id}: "
                             "a one-object export takes an object with one instance per image")  # fmt: skip
        i = found[0]
        return replace(self, mask_visib=i.mask_visib, R=i.R, t=i.t, gt_info=i.gt_info)


@dataclass(frozen=True)
class Source:
    root: Path
    size: tuple[int, int]  # (width, height)
    model_name: str
    samples: tuple[Sample, ...]  # in sample order
    sequence: dict[str, Any] | None = None  # the manifest's `sequence` (count, frames, dt_s), None if none
    object_names: dict[int, str] | None = None  # obj_id -> model name of every object; None: the target only

    @property
    def objects(self) -> dict[int, str]:
        """obj_id -> model name of every labelled object, the target's first."""
        return self.object_names or {OBJ_ID: self.model_name}

    def of_object(self, obj_id: int) -> Source:
        """The dataset as one object's: every sample with that object's pose and labels (Sample.of_object)."""
        samples = tuple(s.of_object(obj_id) for s in self.samples)
        return replace(self, model_name=self.objects[obj_id], samples=samples, object_names=None)

    def split(self, name: str) -> list[Sample]:
        return [s for s in self.samples if s.split == name]

    def relative(self, path: Path) -> str:
        """A dataset file's path relative to the dataset folder, with forward slashes."""
        return path.relative_to(self.root).as_posix()


def read_source(root: str | Path, progress: bool = False) -> Source:
    """Every sample of a finished scgen dataset, each image decoded once; a one-line ScgenError when
    `root` is not one, or names a file it cannot read."""
    # imported here: the command lines' help loads the export registry, and the BOP reader pulls scipy
    from scgen.dataset.bop_dataset import open_bop_dataset

    layout, manifest = open_dataset(root)
    rows = read_metadata(root)
    data = open_bop_dataset(layout.root)
    images = {im.im_id: im for im in data.images}
    if not rows:
        raise ScgenError(f"{root}: metadata.csv lists no samples")
    if sorted(images) != sorted(int(r["sample_id"]) for r in rows):
        raise ScgenError(f"{root}: metadata.csv and the scene_gt.json files list different samples "
                         "(an unfinished render: re-run it to finish)")  # fmt: skip
    scenes: dict[Path, tuple[dict[str, Any], dict[str, Any]]] = {}
    samples = []
    for row in tqdm(rows, desc="export: reading", unit="img", disable=not progress):
        image = images[int(row["sample_id"])]
        scene = data.scene(image)
        if scene not in scenes:
            scenes[scene] = _read(scene, "scene_camera"), _read(scene, "scene_gt_info")
        samples.append(_sample(layout, manifest["rgb_format"], image, row, *scenes[scene]))
    return Source(layout.root, data.size, manifest["model"]["name"], tuple(samples), manifest.get("sequence"),
                  object_names(manifest))  # fmt: skip


def _read(scene: Path, name: str) -> dict[str, Any]:
    return bop.read_json(bop.scene_file(scene, name))


def _sample(layout: Layout, rgb_format: str, image: BopImage, row: dict[str, str],
            cameras: dict[str, Any], infos: dict[str, Any]) -> Sample:  # fmt: skip
    sid, split = image.im_id, image.split
    if row["split"] != split:
        raise ScgenError(f"sample {sid}: in folder '{split}' but metadata.csv says '{row['split']}'")
    obj_id, R, t = image.instances[TARGET_INSTANCE]
    if obj_id != OBJ_ID:
        raise ScgenError(f"sample {sid}: its first scene_gt.json instance is obj_id {obj_id}, not the target")
    rgb = layout.rgb(split, sid, rgb_format)
    if read_image(rgb) is None:  # an export copies or points at it: refused unless it decodes
        raise ScgenError(f"sample {sid}: cannot read {rgb}: {why_unreadable(rgb)}")
    entries = infos.get(str(sid), [])
    if len(entries) != len(image.instances):
        path = bop.scene_file(layout.chunk_dir(split, sid), "scene_gt_info")
        raise ScgenError(f"sample {sid}: {path} has {len(entries)} of its {len(image.instances)} entries")
    pairs = enumerate(zip(image.instances, entries, strict=True))
    instances = tuple(Instance(obj_id, R_k, t_k, layout.mask(split, sid, visib=True, inst=k), info)
                      for k, ((obj_id, R_k, t_k), info) in pairs)  # fmt: skip
    K = np.asarray(image.K, dtype=np.float64).reshape(3, 3)
    return Sample(sid, split, rgb, layout.mask(split, sid, visib=True), R, t, K,
                  np.asarray(bop.camera_dist(cameras[str(sid)])), entries[TARGET_INSTANCE], row,
                  instances)  # fmt: skip
