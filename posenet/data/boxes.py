"""Stored detection boxes: one box per test image, written once and reused by every method (paper §4.1).

The file is BOP's detection format (docs/posenet.md): a JSON list of
{"scene_id", "image_id", "category_id", "bbox": [x, y, w, h] (pixels), "score", "time"}. Where an image
has several entries for the object, the highest score wins. posenet adds two things BOP readers ignore or
skip: a "source" field per entry (`gt`, `gt+noise`, `detector`) and misses, entries with "bbox": [] and
"score": 0, for images where the detector found nothing; evaluation counts those as failures.

Every source holds one kind of box, the one the pose network trains on: `bbox_obj`, the box of the
object's whole silhouette (occluded parts included). `gt` is bbox_obj itself (it may reach past the image);
`gt+noise` and `detector` are it perturbed or detected, clipped to the image (the amodal box GDRNPP's
detectors learn; the detector learns bbox_obj clipped, posenet.detection.detector.target_boxes).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from posenet.data.layout import Instance
from posenet.errors import PosenetError

Box = tuple[float, float, float, float]  # [x, y, w, h]: pixels x .. x + w - 1 (posenet.data.crop)
# The crop a missed image is still read with, so the loader needs no special case; its estimate is discarded
MISS_PLACEHOLDER: Box = (0.0, 0.0, 1.0, 1.0)


def boxes_from_gt(instances: list[Instance], noise: float = 0.0, seed: int = 0) -> list[dict]:
    """Detection entries from the GT full-object boxes (`bbox_obj`), optionally perturbed.

    `noise` is a relative standard deviation: the centre moves by N(0, noise) box sizes per axis and each
    side is scaled by exp(N(0, noise)); the result is clipped to the image.
    """
    rng = np.random.default_rng(seed)
    out = []
    for inst in instances:
        x, y, w, h = (float(v) for v in inst.bbox_obj)
        if noise > 0:
            cx, cy = x + w / 2 + rng.normal(0, noise) * w, y + h / 2 + rng.normal(0, noise) * h
            w, h = w * math.exp(rng.normal(0, noise)), h * math.exp(rng.normal(0, noise))
            x0, y0 = max(cx - w / 2, 0.0), max(cy - h / 2, 0.0)
            x1, y1 = min(cx + w / 2, inst.image_size[0]), min(cy + h / 2, inst.image_size[1])
            x, y, w, h = x0, y0, max(x1 - x0, 1.0), max(y1 - y0, 1.0)
        out.append(
            {
                "scene_id": inst.scene_id,
                "image_id": inst.im_id,
                "category_id": inst.obj_id,
                "bbox": [round(v, 2) for v in (x, y, w, h)],
                "score": 1.0,
                "time": 0.0,
                "source": "gt+noise" if noise > 0 else "gt",
            }
        )
    return out


def box_edges(box: Box) -> tuple[float, float, float, float]:
    """A box [x, y, w, h] (pixels x .. x + w - 1) as the pixel edges [x0, y0, x1, y1] a detector learns and
    gives, where pixel i spans [i, i + 1) (torchvision's boxes; the mask detector's `mask_box`)."""
    x, y, w, h = (float(v) for v in box)
    return x, y, x + w, y + h


def edges_box(edges: np.ndarray | tuple[float, ...]) -> Box:
    """A detector's pixel edges [x0, y0, x1, y1] as the box [x, y, w, h] of the pixels they span (the
    inverse of `box_edges`): what `posenet boxes --detector` writes and predict crops around."""
    x0, y0, x1, y1 = (float(v) for v in edges)
    return x0, y0, x1 - x0, y1 - y0


def clip_box(box: Box, size: tuple[int, int]) -> Box | None:
    """The part of `box` inside an image of `size` (width, height), or None when none is: the amodal box
    a detector can see (GDRNPP's convention), since no pixel past the border is in the image."""
    x0, y0 = max(box[0], 0.0), max(box[1], 0.0)
    x1, y1 = min(box[0] + box[2], float(size[0])), min(box[1] + box[3], float(size[1]))
    if x1 <= x0 or y1 <= y0:
        return None
    return x0, y0, x1 - x0, y1 - y0


def miss_entry(scene_id: int, image_id: int, obj_id: int, time_s: float, source: str) -> dict:
    """The entry of an image where the detector found nothing: no box, score 0."""
    return {"scene_id": scene_id, "image_id": image_id, "category_id": obj_id, "bbox": [], "score": 0.0,
            "time": time_s, "source": source}  # fmt: skip


def _entries(path: Path) -> list[dict]:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise PosenetError(f"cannot read box file {path}: {exc}") from exc


def read_boxes(path: Path, obj_id: int) -> dict[tuple[int, int], Box]:
    """{(scene_id, image_id): best-scoring box of `obj_id`} from a detection file; an image with only
    misses maps to MISS_PLACEHOLDER (see read_misses)."""
    entries = _entries(path)
    best: dict[tuple[int, int], tuple[float, Box]] = {}
    try:
        for e in entries:
            if int(e["category_id"]) != obj_id:
                continue
            if not e["bbox"]:
                best.setdefault((int(e["scene_id"]), int(e["image_id"])), (-math.inf, MISS_PLACEHOLDER))
                continue
            box = tuple(float(v) for v in e["bbox"])
            if len(box) != 4 or box[2] <= 0 or box[3] <= 0:
                raise ValueError(f"bad bbox {e['bbox']}")
            key, score = (int(e["scene_id"]), int(e["image_id"])), float(e.get("score", 1.0))
            if key not in best or score > best[key][0]:
                best[key] = (score, box)
    except (TypeError, KeyError, ValueError) as exc:
        raise PosenetError(f"box file {path} is not a BOP detection list: {exc}") from exc
    return {k: box for k, (_, box) in best.items()}


def read_misses(path: Path, obj_id: int) -> set[tuple[int, int]]:
    """The (scene_id, image_id) of `obj_id` with a miss entry and no box in a detection file."""
    entries = [e for e in _entries(path) if int(e["category_id"]) == obj_id]
    found = {(int(e["scene_id"]), int(e["image_id"])) for e in entries if e["bbox"]}
    return {(int(e["scene_id"]), int(e["image_id"])) for e in entries if not e["bbox"]} - found


def box_source(path: Path) -> str:
    """What a box file holds, from its entries' "source" fields: e.g. `detector`, `gt`, or `unknown`
    (a file without them, such as BOP's default detections)."""
    return "+".join(sorted({str(e.get("source", "unknown")) for e in _entries(path)})) or "empty"
