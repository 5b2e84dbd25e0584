"""COCO instances files, one per split, as detector toolchains read them (pycocotools' encoding).

    OUT/instances_{train,val,test}.json

`file_name` is the image's path relative to the dataset folder (the image root to give a loader). One
category per obj_id (the target, then the config's [[objects]]), named after its model; one annotation
per visible scene_gt instance: bbox = scene_gt_info's bbox_visib in COCO's convention, segmentation = RLE
of mask_visib, area = its pixel count, iscrowd 0. Each image entry also carries the sample's metadata.csv
row (the target's factors) as extra fields.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

import scgen
from scgen.dataset.export.output import ExportFormat
from scgen.dataset.export.source import Instance, Sample, Source
from scgen.dataset.layout import dumps
from scgen.dataset.splits import SPLITS
from scgen.errors import ScgenError
from scgen.io import bop
from scgen.io.image_file import why_unreadable

IMAGE_FIELDS = ("id", "file_name", "width", "height")  # COCO's own keys of an image entry


def instances_file(split: str) -> str:
    return f"instances_{split}.json"


def metadata_value(text: str) -> int | float | str:
    """A metadata.csv cell as JSON: an int or a finite float where it reads as one, the text otherwise."""
    for kind in (int, float):
        try:
            value = kind(text)
        except ValueError:
            continue
        if math.isfinite(value):
            return value
    return text


def image_entry(source: Source, sample: Sample) -> dict[str, Any]:
    extra = {k: metadata_value(v) for k, v in sample.metadata.items()}
    if clash := set(extra) & set(IMAGE_FIELDS):
        raise ScgenError(f"metadata.csv column(s) {', '.join(sorted(clash))} clash with COCO's image keys")
    width, height = source.size
    return {"id": sample.sample_id, "file_name": source.relative(sample.image), "width": width,
            "height": height, **extra}  # fmt: skip


def rle(mask: np.ndarray) -> dict[str, Any]:
    """pycocotools' compressed RLE of a bool mask, its counts as text (JSON holds no bytes)."""
    # imported here: the command lines load the export registry, and posenet's (a training node's) uses
    # none of the encoders
    from pycocotools import mask as mask_utils

    encoded = mask_utils.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(n) for n in encoded["size"]], "counts": encoded["counts"].decode("ascii")}


def annotation(sample: Sample, k: int, instance: Instance, stride: int) -> dict[str, Any]:
    """Instance k's annotation; its id, sample id x `stride` (the most instances of an image) + k + 1, is
    unique in the dataset and never 0, which COCOeval takes for 'no match' (one object: sample id + 1)."""
    visib = bop.read_mask(instance.mask_visib)
    if visib is None:
        path = instance.mask_visib
        raise ScgenError(f"sample {sample.sample_id}: cannot read {path}: {why_unreadable(path)}")
    x, y, w, h = bop.box_pixels(instance.gt_info["bbox_visib"])  # COCO's w, h count pixels: BOP's + 1
    return {"id": sample.sample_id * stride + k + 1, "image_id": sample.sample_id,
            "category_id": instance.obj_id, "bbox": [x, y, w, h],
            "area": int(instance.gt_info["px_count_visib"]), "segmentation": rle(visib),
            "iscrowd": 0}  # fmt: skip


def instances(source: Source, split: str) -> dict[str, Any]:
    samples = source.split(split)
    stride = max(len(s.instances) for s in source.samples)
    return {
        "info": {"description": f"scgen dataset {source.root.resolve()}, split {split}: file_name is "
                                "relative to that folder", "version": scgen.__version__},
        "licenses": [],
        "categories": [{"id": obj_id, "name": name, "supercategory": "spacecraft"}
                       for obj_id, name in source.objects.items()],
        "images": [image_entry(source, s) for s in samples],
        "annotations": [annotation(s, k, i, stride) for s in samples for k, i in enumerate(s.instances)
                        if i.gt_info["px_count_visib"] > 0],
    }  # fmt: skip


def write(source: Source, out: Path) -> dict[str, int]:
    """Write one instances file per split into `out`; returns the number of images per file."""
    counts = {}
    for split in SPLITS:
        content = instances(source, split)
        (out / instances_file(split)).write_text(dumps(content))
        counts[instances_file(split)] = len(content["images"])
    return counts


FORMAT = ExportFormat(
    name="coco",
    summary="one COCO instances file per split (a category per obj_id, masks as RLE, factors per image)",
    layout="OUT/instances_{train,val,test}.json (file_name relative to DATASET)",
    write=write,
)
