"""Mitsuba backend: the time per sample at two image sizes side by side, so the fixed part shows, with the
kernels each sample launches and compiles; then, at 640x480, throughput, time outside the renderer, bytes
per sample by file kind and the float16-vs-float32 xyz storage error. First (--profile) a 640x480 sample's
seconds by stage. Last (--region-n) the old path (the whole frame path-traced) beside the new (a window
over the region the objects cover, scgen.render.mitsuba.window): one worker renders each sample in both,
in turn (A B A B), at --region-size. The other parts run the default (the window; SCGEN_FULL_FRAME=1: the
whole frame).

Each size renders in a fresh worker process, as `scgen render` runs it (scgen.io.parent_watch.spawn_pool),
with --threads renderer threads: one unless given, as a worker of `scgen render` renders
(MITSUBA_THREADS). With more than one, Dr.Jit's idle pool threads busy-wait for a while after each kernel
before they sleep, on cores the worker's own numpy work (backgrounds, the camera stage) then shares, and
the images are not repeatable.
Usage: python benchmarks/bench_mitsuba.py [--n 30] [--warmup 200] [--sizes 64x48,320x240] [--threads N]
       [--full-n 30] [--profile 10] [--region-n 24] [--region-size 640x480] [--out DIR]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import trimesh
from harness import parser, run_script

from scgen import Generator
from scgen.annotate import annotate
from scgen.dataset.layout import DATASET_FILES, Layout, bytes_by_kind
from scgen.dataset.splits import plan_splits
from scgen.dataset.validate import reprojection_error
from scgen.dataset.writer import WriteOptions, finalize, resolved, write_sample
from scgen.io.parent_watch import spawn_pool
from scgen.render.base import create_backend
from scgen.run.runner import write_static_files
from scgen.scenes import load_config
from scgen.scenes.factors import spec_key
from scgen.scenes.model import load_target


def time_size(
    size: tuple[int, int], n: int, quality: str, seed: int, threads: int | None, warmup: int
) -> dict:
    """In a worker: samples warmup..warmup+n-1 of `seed` at `size` after the samples before them (a
    warm-up); per sample the seconds of the render and of the annotation, CPU seconds, kernel launches,
    kernels compiled and whether the render was traced and recorded (else it replayed a recording)."""
    import drjit as dr

    model = load_target()
    backend = create_backend("mitsuba", model, quality=quality, threads=threads)
    generator = Generator(model, load_config(resolution=size), seed)
    dr.set_flag(dr.JitFlag.KernelHistory, True)  # from the start: a frozen render is keyed by the JIT flags
    for i in range(warmup):
        backend.render(generator.scene(i))
        dr.kernel_history()
    out: dict[str, list[float]] = defaultdict(list)
    for i in range(warmup, warmup + n):
        recordings = getattr(backend, "recordings", 0)  # 0 for code from before the frozen render
        spec = generator.scene(i)
        t0, c0 = time.perf_counter(), time.process_time()
        buffers = backend.render(spec)
        t1 = time.perf_counter()
        annotate(spec, buffers)
        out["render"].append(t1 - t0)
        out["annotate"].append(time.perf_counter() - t1)
        out["cpu"].append(time.process_time() - c0)
        history = dr.kernel_history()
        out["launches"].append(len(history))
        out["compiled"].append(sum(1 for k in history if k.get("cache_hit") == 0))
        out["recorded"].append(getattr(backend, "recordings", 0) - recordings)
    return {"variant": backend.variant, "spp": backend.spp, "threads": dr.thread_count(), **out}


def side_by_side(
    sizes: list[tuple[int, int]], n: int, quality: str, seed: int, threads: int | None, warmup: int
) -> None:
    """The per-sample figures of each size, one column each, and the fixed part of a straight-line fit."""
    results = []
    for size in sizes:
        with spawn_pool(1) as pool:
            results.append(pool.submit(time_size, size, n, quality, seed, threads, warmup).result())
    r0 = results[0]
    print(
        f"Mitsuba ({r0['variant']}, {quality}, {r0['spp']} spp, {r0['threads']} renderer thread(s)), seed "
        f"{seed}: samples {warmup}-{warmup + n - 1} after {warmup} warm-up samples, each size in a fresh "
        "worker process"
    )
    print(f"  {'per sample':<30s}" + "".join(f"{f'{w}x{h}':>12s}" for w, h in sizes))
    rows = [
        ("render, median ms", lambda r: 1000 * np.median(r["render"])),
        ("render, mean ms", lambda r: 1000 * np.mean(r["render"])),
        ("render + annotate, median ms", lambda r: 1000 * np.median(np.add(r["render"], r["annotate"]))),
        ("CPU ms (all threads), median", lambda r: 1000 * np.median(r["cpu"])),
        ("kernel launches, median", lambda r: np.median(r["launches"])),
        ("kernels compiled, mean", lambda r: np.mean(r["compiled"])),
        ("renders traced and recorded, %", lambda r: 100 * np.mean(r["recorded"])),
    ]
    for label, value in rows:
        print(f"  {label:<30s}" + "".join(f"{value(r):12.1f}" for r in results))
    if len(sizes) == 2:
        pixels = [w * h for w, h in sizes]
        t = [np.median(r["render"]) for r in results]
        per_px = (t[1] - t[0]) / (pixels[1] - pixels[0])
        fixed = t[0] - per_px * pixels[0]
        print(f"  straight line through the medians: {1000 * fixed:.1f} ms fixed + {1e6 * per_px:.2f} ms per")
        print(f"  1000 pixels ({100 * fixed / t[0]:.0f} % of a {sizes[0][0]}x{sizes[0][1]} render is fixed)")


MODES = {"full frame": False, "window": True}  # MitsubaBackend.trace_region: the old path, then the new


def time_modes(size: tuple[int, int], n: int, quality: str, seed: int, warmup: int) -> dict[str, dict]:
    """In a worker: samples warmup..warmup+n-1 of `seed` at `size`, each rendered and annotated once per
    mode in turn after the samples before them in both modes (a warm-up: a new window size compiles its
    kernels and records its render); per mode and sample the seconds, kernels compiled, renders recorded
    and the share of the frame path-traced."""
    import drjit as dr

    model = load_target()
    backend = create_backend("mitsuba", model, quality=quality)
    generator = Generator(model, load_config(resolution=size), seed)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    runs: dict[str, dict[str, list[float]]] = {m: defaultdict(list) for m in MODES}
    for i in range(warmup + n):
        spec = generator.scene(i)
        for mode, trace_region in MODES.items():
            backend.trace_region = trace_region
            dr.kernel_history()
            recordings = backend.recordings
            t0 = time.perf_counter()
            buffers = backend.render(spec)
            t1 = time.perf_counter()
            annotate(spec, buffers)
            if i < warmup:
                continue
            r = runs[mode]
            r["render"].append(t1 - t0)
            r["sample"].append(time.perf_counter() - t0)
            r["compiled"].append(sum(1 for k in dr.kernel_history() if k.get("cache_hit") == 0))
            r["recorded"].append(backend.recordings - recordings)
            r["share"].append(backend.window.share)
    return {m: dict(r) for m, r in runs.items()}


def region_side_by_side(size: tuple[int, int], n: int, quality: str, seed: int, warmup: int) -> None:
    """The full frame's per-sample figures beside the window's, one worker, A B A B."""
    with spawn_pool(1) as pool:
        runs = pool.submit(time_modes, size, n, quality, seed, warmup).result()
    print(
        f"\nMitsuba {size[0]}x{size[1]} ({quality}), seed {seed}: samples {warmup}-{warmup + n - 1} after "
        f"{warmup} warm-up samples, one worker, each sample in both modes in turn (A B A B)"
    )
    print(f"  {'per sample':<32s}" + "".join(f"{m:>12s}" for m in MODES))
    rows = [
        ("render, median s", lambda r: np.median(r["render"])),
        ("render, mean s", lambda r: np.mean(r["render"])),
        ("render + annotate, median s", lambda r: np.median(r["sample"])),
        ("pixels path-traced, median %", lambda r: 100 * np.median(r["share"])),
        ("kernels compiled, mean", lambda r: np.mean(r["compiled"])),
        ("renders recorded, %", lambda r: 100 * np.mean(r["recorded"])),
    ]
    for label, value in rows:
        print(f"  {label:<32s}" + "".join(f"{value(runs[m]):12.3f}" for m in MODES))
    full, window = (np.mean(runs[m]["sample"]) for m in MODES)
    ratios = np.divide(runs["window"]["sample"], runs["full frame"]["sample"])
    print(f"  window / full frame: {window / full:.3f} of the mean time per sample (median per-sample ratio "
          f"{np.median(ratios):.3f})")  # fmt: skip


def full_size(n: int, quality: str, out: Path) -> None:
    """640x480 samples rendered, annotated and written as `scgen render` does: throughput, the share of
    time outside the renderer, bytes per sample by file kind and the xyz storage error."""
    model, cfg = load_target(), load_config()
    backend = create_backend("mitsuba", model, quality=quality)
    generator = Generator(model, cfg, 0)
    write = resolved(WriteOptions(), generator.cfg["camera"])  # as a run writes: the camera's format
    specs = [generator.scene(i) for i in range(n)]
    splits = plan_splits([spec_key(s) for s in specs], (0.7, 0.1, 0.2), 0)
    layout = Layout(out)
    write_static_files(layout, generator)
    surface = trimesh.proximity.ProximityQuery(model.mesh)
    backend.render(specs[0])  # warm-up (JIT compilation)
    t_render = t_other = 0.0
    errors: dict[str, list[np.ndarray]] = defaultdict(list)
    for spec, split in zip(specs, splits, strict=True):
        t0 = time.perf_counter()
        buffers = backend.render(spec)
        t1 = time.perf_counter()
        ann = annotate(spec, buffers)
        write_sample(layout, spec, buffers, ann, split, write)
        t2 = time.perf_counter()
        t_render += t1 - t0
        t_other += t2 - t1
        vs, us = np.nonzero(ann.mask_visib)
        for dtype in ("float16", "float32"):
            C = ann.xyz[vs, us].astype(dtype).astype(np.float64)
            errors[f"{dtype} reproj px"].append(
                reprojection_error(C, us, vs, spec.camera, spec.target.R_mat, spec.target.t_vec)
            )
            errors[f"{dtype} surface mm"].append(surface.on_surface(C)[1] * 1000)
    finalize(layout)
    total = t_render + t_other
    print(f"Mitsuba ({backend.variant}, {quality}, 640x480), {n} samples")
    print(f"  images/s: {n / total:.2f}   render {t_render / n:.3f} s/img")
    print(f"  time outside the renderer (annotation + writing): {100 * t_other / total:.1f} %")
    sizes = bytes_by_kind(out)
    static = sizes.pop(DATASET_FILES)  # models, models_eval, camera, config, test targets, metadata
    print(f"  files written once per dataset: {static / 2**20:.1f} MB")
    print("  bytes per sample by file kind:")
    for kind, b in sorted(sizes.items()):
        print(f"    {kind:<11s} {b / n / 1024:8.1f} KB")
    per = sum(sizes.values()) / n
    print(f"    {'total':<11s} {per / 1024:8.1f} KB  -> 50k samples: {per * 50000 / 1e9:.1f} GB")
    print("  xyz storage error (all visible pixels): p99 / max")
    for name, vals in errors.items():
        v = np.concatenate(vals)
        print(f"    {name:<18s} {np.percentile(v, 99):.4f} / {v.max():.4f}")


def stage_profile(n: int, quality: str, out: Path) -> None:
    """Median seconds per stage of a 640x480 sample (after a warm-up that records the renders): the
    backend's own steps, timed around its methods, then annotation and writing."""
    import scgen.render.mitsuba.backend as mitsuba_backend

    model = load_target()
    backend = create_backend("mitsuba", model, quality=quality)
    generator = Generator(model, load_config(), 0)
    write = resolved(WriteOptions(), generator.cfg["camera"])  # as a run writes: the camera's format
    layout = Layout(out)
    write_static_files(layout, generator)
    times: dict[str, list[float]] = defaultdict(list)

    def timed(owner: object, name: str, stage: str) -> None:
        fn = getattr(owner, name)

        def wrapper(*a, **kw):
            t0 = time.perf_counter()
            result = fn(*a, **kw)
            times[stage].append(time.perf_counter() - t0)
            return result

        setattr(owner, name, wrapper)

    stages = {"_fill": "meshes into slots", "_scene": "scene: BVH rebuild, lights",
              "_passes": "label ray casts", "_render": "path tracing (frozen replay)"}  # fmt: skip
    for name, stage in stages.items():
        timed(backend, name, stage)
    timed(mitsuba_backend, "background_image", "background")
    timed(mitsuba_backend, "record_image", "camera stage")
    for i in range(n + 5):
        if i == 5:  # the first samples record the renders: not what a long run sees
            times.clear()
        spec = generator.scene(i)
        t0 = time.perf_counter()
        buffers = backend.render(spec)
        t1 = time.perf_counter()
        ann = annotate(spec, buffers)
        t2 = time.perf_counter()
        write_sample(layout, spec, buffers, ann, "train", write)
        t3 = time.perf_counter()
        times["annotation"].append(t2 - t1)
        times["writing"].append(t3 - t2)
        times["sample (total)"].append(t3 - t0)
    print(f"\nMitsuba stages of one 640x480 sample ({quality}), median of {n} after 5 warm-up samples, s")
    for stage, values in times.items():
        print(f"  {stage:32s} {np.median(values):8.3f}")


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--n", type=int, default=30, help="samples per size, side by side")
    ap.add_argument(
        "--warmup",
        type=int,
        default=200,
        help="samples rendered before the timed ones (a worker's first ones record its renders)",
    )
    ap.add_argument("--sizes", default="64x48,320x240")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--full-n", type=int, default=30, help="samples at 640x480 (0: skip)")
    ap.add_argument("--profile", type=int, default=10, help="640x480 samples profiled by stage (0: skip)")
    ap.add_argument("--region-n", type=int, default=24, help="samples in both modes, side by side (0: skip)")
    ap.add_argument("--region-warmup", type=int, default=8, help="samples in both modes before those timed")
    ap.add_argument("--region-size", default="640x480")
    ap.add_argument("--quality", default="default")
    ap.add_argument("--threads", type=int, default=None, help="renderer threads per worker [one]")
    ap.add_argument("--out", type=Path, default=None)
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    sizes = [(int(w), int(h)) for w, h in (s.split("x") for s in args.sizes.split(","))]
    if args.profile:
        stage_profile(args.profile, args.quality, Path(tempfile.mkdtemp()) / "profile")
    if args.n:
        side_by_side(sizes, args.n, args.quality, args.seed, args.threads, args.warmup)
    if args.full_n:
        full_size(args.full_n, args.quality, args.out or Path(tempfile.mkdtemp()) / "bench")
    if args.region_n:
        size = tuple(int(x) for x in args.region_size.split("x"))
        region_side_by_side(size, args.region_n, args.quality, args.seed, args.region_warmup)


if __name__ == "__main__":
    run_script(run, parse_args())
