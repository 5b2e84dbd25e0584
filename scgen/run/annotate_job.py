"""`scgen annotate`: exact xyz maps, masks and scene_gt_info for every instance of any BOP dataset.

Per image, one Mitsuba scene holds every scene_gt instance placed by its pose; one ray per pixel centre
gives the first hit (visible mask, depth, then xyz = Rᵀ(z·K⁻¹p̄ − t)), and each instance cast alone
gives its full mask. Objects that scene_gt does not list are not in the scene, so they occlude nothing
there: where the dataset has its own mask_visib, that mask is the authority (xyz is zero outside it), and
the pixels where it and the ray cast disagree are counted per instance in the image's record and per
split in the run's summary.

Resumable like `render`: an image's files are written atomically and its record
`{scene}/annotate/{im_id:06d}.json` last; an image is done when its record and every file the record
lists exist. scene_gt_info.json of a scene is written once all its images are done, from the records.
The dataset's own masks and scene_gt_info values are kept (only `xyz_box` is added) unless `overwrite`.
"""

from __future__ import annotations

import sys
import time
from collections import defaultdict
from concurrent.futures import as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from scgen.annotate.bop_labels import InstanceLabels, VisibDisagreement, instance_labels
from scgen.dataset.bop_dataset import BopDataset, BopImage, open_bop_dataset, read_models
from scgen.dataset.layout import dumps
from scgen.dataset.writer import encode_png
from scgen.errors import ScgenError
from scgen.io import bop
from scgen.io.atomic import atomic_write_bytes, atomic_write_text, remove_stale_temporaries
from scgen.io.bop import read_json
from scgen.io.cores import usable_cores
from scgen.io.exr import encode_xyz_exr
from scgen.io.parent_watch import spawn_pool
from scgen.render.mitsuba import raycast
from scgen.scenes.projection import projection_box

RECORDS_DIR = "annotate"
Models = dict[int, tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class AnnotateOptions:
    xyz_dtype: str = "float16"
    overwrite: bool = False  # replace the dataset's own masks and scene_gt_info (and redo every image)


@dataclass(frozen=True)
class AnnotateJob:
    root: Path
    split: str | None = None  # None: every split
    workers: int = 1
    options: AnnotateOptions = field(default_factory=AnnotateOptions)


def record_path(scene: Path, im_id: int) -> Path:
    return scene / RECORDS_DIR / f"{im_id:06d}.json"


def kept(path: Path, opts: AnnotateOptions) -> bool:
    """Whether the dataset's own file at `path` stays: it exists and `overwrite` is off."""
    return not opts.overwrite and path.is_file()


def own_visib_masks(data: BopDataset, image: BopImage, opts: AnnotateOptions) -> list[np.ndarray | None]:
    """The image's kept mask_visib of every instance, in scene_gt order (None where there is none)."""
    out: list[np.ndarray | None] = []
    for k in range(len(image.instances)):
        path = bop.mask_path(data.scene(image), image.im_id, k, visib=True)
        if not kept(path, opts):
            out.append(None)
            continue
        mask = bop.read_mask(path)
        if mask is None or mask.shape != data.size[::-1]:
            raise ScgenError(f"{path} is unreadable or not {data.size[0]}x{data.size[1]}")
        out.append(mask)
    return out


def label_image(data: BopDataset, image: BopImage, models: Models,
                own_visib: list[np.ndarray | None]) -> list[InstanceLabels]:  # fmt: skip
    """Labels of every scene_gt instance of one image, in scene_gt order, given the kept mask_visib."""
    camera = data.camera(image)
    shapes = [raycast.place_mesh(f"inst{k}", *models[obj_id], R, t)
              for k, (obj_id, R, t) in enumerate(image.instances)]  # fmt: skip
    index, depth = raycast.cast(shapes, camera, (0, 0, camera.width, camera.height))
    labels = []
    for k, ((obj_id, R, t), shape) in enumerate(zip(image.instances, shapes, strict=True)):
        box = projection_box(models[obj_id][0], R, t, camera)
        full = raycast.cast([shape], camera, box)[0] == 0 if box else np.zeros((0, 0), bool)
        labels.append(instance_labels(k, index, depth, full, box or (0, 0, 0, 0), camera, R, t, own_visib[k]))
    return labels


def write_image(scene: Path, im_id: int, labels: list[InstanceLabels], opts: AnnotateOptions) -> None:
    """The image's masks (where missing, or all with overwrite) and xyz maps, then its record."""
    files = []
    for k, lab in enumerate(labels):
        for visib, mask in ((False, lab.mask), (True, lab.mask_visib)):
            path = bop.mask_path(scene, im_id, k, visib)
            if not kept(path, opts):
                path.parent.mkdir(parents=True, exist_ok=True)
                atomic_write_bytes(path, encode_png(mask.astype(np.uint8) * 255))
            files.append(path)
        path = bop.xyz_path(scene, im_id, k)
        if lab.xyz is None:
            path.unlink(missing_ok=True)
            continue
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, encode_xyz_exr(lab.xyz, opts.xyz_dtype))
        files.append(path)
    record = {"files": [str(p.relative_to(scene)) for p in files], "overwrite": opts.overwrite,
              "xyz_dtype": opts.xyz_dtype, "scene_gt_info": [lab.gt_info for lab in labels],
              "visib_disagreement": [asdict(lab.disagreement) for lab in labels]}  # fmt: skip
    path = record_path(scene, im_id)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, dumps(record))


def done_record(scene: Path, im_id: int, opts: AnnotateOptions) -> dict[str, Any] | None:
    """The image's record if the image is complete on disk for these options, else None."""
    path = record_path(scene, im_id)
    if not path.is_file():
        return None
    record = read_json(path)
    if record.get("xyz_dtype") != opts.xyz_dtype or (opts.overwrite and not record.get("overwrite")):
        return None
    return record if all((scene / f).is_file() for f in record["files"]) else None


def finalize(data: BopDataset, opts: AnnotateOptions) -> int:
    """Write scene_gt_info.json of every scene whose images are all done; returns how many."""
    scenes: dict[Path, list[BopImage]] = defaultdict(list)
    for image in data.images:
        scenes[data.scene(image)].append(image)
    n = 0
    for scene, images in scenes.items():
        records = {str(im.im_id): done_record(scene, im.im_id, opts) for im in images}
        if any(r is None for r in records.values()):
            continue
        path = bop.scene_file(scene, "scene_gt_info")
        theirs = {} if opts.overwrite or not path.is_file() else read_json(path)
        info = {im: with_xyz_boxes(theirs.get(im), r["scene_gt_info"]) for im, r in records.items()}
        atomic_write_text(path, dumps(info))
        n += 1
    return n


def with_xyz_boxes(theirs: list[dict[str, Any]] | None, ours: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The dataset's own entries of an image with our xyz_box added, or ours where it has none."""
    if theirs is None or len(theirs) != len(ours):
        return ours
    return [{**t, "xyz_box": o["xyz_box"]} for t, o in zip(theirs, ours, strict=True)]


@dataclass(frozen=True)
class _Context:
    """What every worker needs: picklable, sent once per worker process."""

    data: BopDataset
    models: Models
    opts: AnnotateOptions
    threads: int


_context: _Context | None = None


def _init(context: _Context) -> None:
    global _context
    _context = context
    raycast.start(context.threads)


def _annotate(image: BopImage) -> tuple[int, VisibDisagreement]:
    """Label and write one image; returns its instance count and its disagreement with its own masks."""
    assert _context is not None
    data, opts = _context.data, _context.opts
    try:
        labels = label_image(data, image, _context.models, own_visib_masks(data, image, opts))
        write_image(data.scene(image), image.im_id, labels, opts)
    except Exception as exc:
        raise ScgenError(f"{image.split}/{image.scene_id:06d} image {image.im_id}: {exc}") from exc
    return len(labels), sum((lab.disagreement for lab in labels), VisibDisagreement())


def disagreement_line(per_split: dict[str, VisibDisagreement]) -> str:
    """The run's disagreement with the dataset's own mask_visib, in one line."""
    parts = [f"{s} {d.cast_only} / {d.mask_only}" for s, d in sorted(per_split.items())]
    return ("visibility vs the dataset's mask_visib (px seen only by the ray cast / only in mask_visib): "
            f"{', '.join(parts) or 'no images annotated'}")  # fmt: skip


def run_annotate(job: AnnotateJob, progress: bool = True) -> dict[str, Any]:
    """Annotate the job's images that are not done yet, then write scene_gt_info; returns a summary."""
    if job.workers <= 0:
        raise ScgenError(f"--workers must be positive, got {job.workers}")
    data = open_bop_dataset(job.root, job.split)
    threads = max(1, usable_cores() // job.workers)
    # workers get the dataset without its image list: each task carries its own image
    context = _Context(replace(data, images=()), read_models(data), job.options, threads)
    for split in sorted({im.split for im in data.images}):
        remove_stale_temporaries(data.root / split)
    todo = [im for im in data.images if done_record(data.scene(im), im.im_id, job.options) is None]
    bar = tqdm(total=len(todo), unit="img", desc="annotate", disable=not progress, file=sys.stderr)
    results: list[tuple[str, int, VisibDisagreement]] = []  # split, instances, disagreement per image
    t0 = time.perf_counter()
    try:
        if job.workers == 1 and todo:
            _init(context)
            for image in todo:
                results.append((image.split, *_annotate(image)))
                bar.update(1)
        elif todo:
            workers = min(job.workers, len(todo))
            pool = spawn_pool(workers, _init, (context,))
            try:
                futures = {pool.submit(_annotate, image): image for image in todo}
                for fut in as_completed(futures):
                    results.append((futures[fut].split, *fut.result()))
                    bar.update(1)
            except BrokenProcessPool as exc:
                raise ScgenError("a worker process died; run the same command again to resume") from exc
            finally:
                pool.shutdown(cancel_futures=True)  # after a failure, start no more images
    finally:
        bar.close()
        scenes = finalize(data, job.options)  # complete scenes stay usable, even after a failure
    disagreement: dict[str, VisibDisagreement] = defaultdict(VisibDisagreement)
    for split, _, d in results:
        disagreement[split] += d
    return {"annotated": len(todo), "skipped": len(data.images) - len(todo),
            "instances": sum(n for _, n, _ in results), "total_s": time.perf_counter() - t0,
            "scenes": scenes, "disagreement": dict(disagreement)}  # fmt: skip
