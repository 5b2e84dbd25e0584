"""Plan and run a render: validate everything, plan splits up front, render missing samples, finalize."""

from __future__ import annotations

import hashlib
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tqdm import tqdm

import scgen
from scgen.dataset.layout import FORMAT, MANIFEST, OBJ_ID, Layout, dumps
from scgen.dataset.model_files import write_eval_model_dir, write_model_dir
from scgen.dataset.splits import SPLITS, plan_splits, split_lists
from scgen.dataset.writer import (
    WriteOptions,
    dataset_depth_scale,
    existing_sample_ids,
    finalize,
    resolved,
)
from scgen.errors import ScgenError
from scgen.generator import Generator
from scgen.io.atomic import atomic_write_text, remove_stale_temporaries
from scgen.io.bop import read_json
from scgen.io.output_path import check_output, make_output_folder, writing
from scgen.io.parent_watch import spawn_pool
from scgen.render.base import check_backend, renderer_threads
from scgen.render.conventions import check_quality
from scgen.run.executors import run_local, run_ray
from scgen.run.worker import Done, Task, WorkerSettings
from scgen.scenes.factors import spec_key
from scgen.scenes.lens import is_pinhole
from scgen.scenes.motion.sequence import is_sequence
from scgen.scenes.spec import SceneSpec


@dataclass
class RenderJob:
    """Everything `scgen render` was asked to do."""

    out: Path
    n: int
    seed: int = 0
    backend: str = "blender"
    quality: str = "default"
    device: str = "auto"
    model_path: Path | None = None
    keep_scale: bool = False
    config_path: Path | None = None
    camera: str | None = None  # camera preset (scgen.scenes.config.camera)
    overrides: dict[str, Any] = field(default_factory=dict)
    resolution: tuple[int, int] | None = None
    split_by: str = "factors"
    ratios: tuple[float, float, float] = (0.7, 0.1, 0.2)
    shard: tuple[int, int] = (0, 1)
    workers: int = 1
    threads: int | None = None  # renderer threads per worker; None = the backend's (renderer_threads)
    executor: str = "local"
    ray_address: str | None = None
    write: WriteOptions = field(default_factory=WriteOptions)


@dataclass
class Plan:
    """The resolved inputs of a job: its generator (model, config), every SceneSpec and its split."""

    generator: Generator
    specs: list[SceneSpec]
    splits: list[str]
    keys: list[str]
    write: WriteOptions  # the job's, its rgb format resolved for the camera (never auto)

    @property
    def n_samples(self) -> int:
        """Samples (images) of the job: --n, or --n sequences of the config's frames each."""
        return len(self.specs)


def validate_job(job: RenderJob) -> None:
    """Checks that need no heavy work; raise ScgenError naming the bad value."""
    if job.n <= 0:
        raise ScgenError(f"--n must be a positive number of samples, got {job.n}")
    check_backend(job.backend, job.device)  # the renderer can start here (builds none)
    check_quality(job.quality)
    if job.workers <= 0:
        raise ScgenError(f"--workers must be positive, got {job.workers}")
    if job.executor not in ("local", "ray"):
        raise ScgenError(f"unknown executor '{job.executor}' (choose local or ray)")
    i, count = job.shard
    if count <= 0 or not 0 <= i < count:
        raise ScgenError(f"--shard must be i/N with 0 <= i < N, got {i}/{count}")
    if job.out.exists() and not job.out.is_dir():
        raise ScgenError(f"output {job.out} exists and is not a directory")
    if job.out.is_dir() and any(job.out.iterdir()) and not (job.out / MANIFEST).exists():
        raise ScgenError(f"output {job.out} is a non-empty folder that is not an scgen dataset")
    check_output(job.out, folder=True, overwrite=True)


def make_plan(job: RenderJob) -> Plan:
    generator = Generator.load(
        job.model_path, job.config_path, job.seed, job.resolution, job.keep_scale, job.overrides, job.camera,
        backend=job.backend, quality=job.quality, device=job.device,
        threads=renderer_threads(job.backend, job.workers, job.threads),
    )  # fmt: skip
    specs = sample_all(generator, job.n * generator.frames, job.workers)
    if is_sequence(generator.cfg):
        keys, splits = sequence_splits(specs, generator.frames, job)
    else:
        keys = [spec_key(s) for s in specs]
        splits = plan_splits(keys, job.ratios, job.seed, job.split_by)
    return Plan(generator, specs, splits, keys, resolved(job.write, generator.cfg["camera"]))


def sequence_splits(specs: list[SceneSpec], frames: int, job: RenderJob) -> tuple[list[str], list[str]]:
    """(key, split) of every frame, whole sequences to one split: planned over the sequences, each keyed
    by its motion (profile and attitude mode: a factor split holds motions unseen in training), or at
    random with --split-by random."""
    firsts = specs[::frames]
    keys = [f"{s.sequence.profile}|{s.sequence.attitude}" for s in firsts if s.sequence]
    splits = plan_splits(keys, job.ratios, job.seed, job.split_by)
    return [k for k in keys for _ in range(frames)], [s for s in splits for _ in range(frames)]


def _sample_range(args: tuple[Generator, range]) -> list[SceneSpec]:
    generator, indices = args
    return [generator.scene(i) for i in indices]


def sample_all(generator: Generator, n: int, workers: int) -> list[SceneSpec]:
    """Every SceneSpec of the job (needed up front for the split plan), in parallel when n is large."""
    if workers <= 1 or n < 500:
        return _sample_range((generator, range(n)))
    step = -(-n // (4 * workers))
    chunks = [(generator, range(a, min(n, a + step))) for a in range(0, n, step)]
    with spawn_pool(workers) as pool:
        return [spec for part in pool.map(_sample_range, chunks) for spec in part]


def manifest_for(job: RenderJob, plan: Plan) -> dict[str, Any]:
    """What identifies a dataset: a resume or a shard must match it exactly."""
    cfg_text = json.dumps(plan.generator.cfg, sort_keys=True)
    return {
        "format": FORMAT,
        "scgen_version": scgen.__version__,
        "seed": job.seed,
        "n": job.n,
        "backend": job.backend,
        "quality": job.quality,
        "model": {"name": plan.generator.model.name, "fingerprint": plan.generator.model.fingerprint,
                  "diameter_m": plan.generator.model.diameter},
        **objects_manifest(plan.generator),
        "config_sha256": hashlib.sha256(cfg_text.encode()).hexdigest(),
        "split_by": job.split_by,
        "split_ratios": list(job.ratios),
        "rgb_format": plan.write.rgb_format,
        "xyz_dtype": plan.write.xyz_dtype,
        "save_depth": plan.write.save_depth,
        **sequence_manifest(plan.generator.cfg, job.n),
    }  # fmt: skip


def objects_manifest(generator: Generator) -> dict[str, Any]:
    """The manifest's `objects` entry (a dataset with `[[objects]]` only): each further object's obj_id,
    name, fingerprint and diameter, so a resume refuses another model behind the same path."""
    others = {k: m for k, m in generator.models.items() if k != OBJ_ID}
    if not others:
        return {}
    return {"objects": {str(k): {"name": m.name, "fingerprint": m.fingerprint, "diameter_m": m.diameter}
                        for k, m in others.items()}}  # fmt: skip


def sequence_manifest(cfg: dict[str, Any], n: int) -> dict[str, Any]:
    """The manifest's `sequence` entry (a sequence dataset only): what Layout reads its scene size from."""
    if not is_sequence(cfg):
        return {}
    return {"sequence": {"count": n, "frames": cfg["sequence"]["frames"], "dt_s": cfg["sequence"]["dt_s"]}}


def write_static_files(layout: Layout, generator: Generator, frames: list[SceneSpec] | None = None) -> None:
    """The files every sample's writer reads: camera.json (with the dataset's depth scale: to the
    farthest of `frames` where given, a sequence dataset's, else of the config's distance ranges),
    config.json, the BOP models and the evaluation models."""
    make_output_folder(layout.root)
    cam = generator.cfg["camera"]
    entries = [(d.obj_id, d.entry) for d in generator.object_draws]
    depth_scale = dataset_depth_scale(generator.cfg, generator.models, entries, frames)
    camera = {"cx": cam["cx"], "cy": cam["cy"], "fx": cam["fx"], "fy": cam["fy"], "width": cam["width"],
              "height": cam["height"], "depth_scale": depth_scale}  # fmt: skip
    if not is_pinhole(tuple(cam["dist"])):  # the lens, as each image's scene_camera entry has it
        camera["cam_dist"] = [float(k) for k in cam["dist"]]
    atomic_write_text(layout.camera_path, dumps(camera))
    atomic_write_text(layout.config_path, dumps(generator.cfg))
    write_model_dir(generator.models, layout.models_dir)
    write_eval_model_dir(generator.models, layout.models_eval_dir)


def prepare_output(job: RenderJob, plan: Plan) -> Layout:
    """Create the dataset folder and its static files, or check that an existing one matches."""
    layout = Layout(job.out, plan.generator.frames if is_sequence(plan.generator.cfg) else None)
    manifest = manifest_for(job, plan)
    if layout.manifest_path.exists():
        old = read_json(layout.manifest_path)
        diff = sorted(k for k in manifest.keys() | old.keys() if manifest.get(k) != old.get(k))
        if diff:
            details = ", ".join(f"{k}: {old.get(k)!r} on disk vs {manifest.get(k)!r} now" for k in diff)
            raise ScgenError(
                f"refusing to resume into {job.out}: it was made with different settings ({details})"
            )
        remove_stale_temporaries(layout.root)
        return layout
    frames = plan.specs if is_sequence(plan.generator.cfg) else None
    with writing(job.out):  # a failure (a full disk) is one line, and a new OUT is removed again
        write_static_files(layout, plan.generator, frames)
        atomic_write_text(
            layout.splits_path,
            dumps({"split_by": job.split_by, "ratios": list(job.ratios), "seed": job.seed,
                   "splits": split_lists(plan.splits), "keys": {str(i): k for i, k in enumerate(plan.keys)}}),
        )  # fmt: skip
        atomic_write_text(layout.manifest_path, dumps(manifest))  # last: its presence marks a dataset
    return layout


def shard_indices(n: int, shard: tuple[int, int]) -> list[int]:
    """Indices of shard i of N: every N-th index starting at i (balances cheap and costly samples)."""
    i, count = shard
    return list(range(i, n, count))


def run_render(job: RenderJob, progress: bool = True) -> dict[str, Any]:
    """Render the job's missing samples and finalize; returns a summary with timings: plan_s (sampling
    every SceneSpec, the split plan, the static files), render_wall_s, finalize_s, and the workers'
    summed render_s/other_s."""
    t_plan = time.perf_counter()
    validate_job(job)
    plan = make_plan(job)
    layout = prepare_output(job, plan)
    done = existing_sample_ids(layout)
    tasks = [
        Task(i, plan.splits[i], plan.specs[i].to_dict())
        for i in shard_indices(plan.n_samples, job.shard)
        if i not in done
    ]
    settings = WorkerSettings(plan.generator, job.out, plan.write)
    timings = {"plan_s": time.perf_counter() - t_plan, "render_s": 0.0, "other_s": 0.0}
    bar = tqdm(
        total=len(tasks), unit="img", disable=not progress, file=sys.stderr, desc="render", smoothing=0.1
    )

    def on_done(d: Done) -> None:
        timings["render_s"] += d.render_s
        timings["other_s"] += d.other_s
        bar.update(1)

    t0 = time.perf_counter()
    try:
        if job.executor == "ray":
            gpus = 1.0 if job.device == "gpu" else 0.0
            run_ray(tasks, settings, job.workers, job.ray_address, gpus, on_done)
        else:
            run_local(tasks, settings, job.workers, on_done)
    finally:
        bar.close()
        timings["render_wall_s"] = time.perf_counter() - t0
        n_done = finalize(layout)  # whatever is complete stays usable, even after a failure
        timings["finalize_s"] = time.perf_counter() - t0 - timings["render_wall_s"]
    return {
        "rendered": len(tasks),
        "skipped": len(done),
        "complete": n_done,
        "total": plan.n_samples,
        "total_s": time.perf_counter() - t0,
        **timings,
        "splits": {s: plan.splits.count(s) for s in SPLITS},
    }
