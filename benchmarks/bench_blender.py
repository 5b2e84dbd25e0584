"""Blender backend benchmark: speed per annotated sample, time outside Cycles, RSS, naive rebuild, presets.

One worker renders `--frames` sampled scenes (640x480 by default) with one persistent backend,
annotating and writing each sample as `scgen render` does; then `--naive-frames` of the same
scenes with a backend rebuilt for every frame; then the quality presets against a many-sample
reference (PSNR over the rendered objects, so the composited background does not inflate it).

    .venv/bin/python benchmarks/bench_blender.py                      # 30 frames, naive, presets
    .venv/bin/python benchmarks/bench_blender.py --frames 300 --naive-frames 0 --preset-frames 0
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

import cv2
import numpy as np
from harness import parser, run_script

from scgen import Generator
from scgen.annotate import annotate
from scgen.dataset.layout import Layout
from scgen.dataset.writer import WriteOptions, write_sample
from scgen.render.blender.backend import BlenderBackend
from scgen.render.blender.settings import PRESETS, QualityPreset, configure_beauty
from scgen.run.runner import write_static_files
from scgen.scenes import load_config
from scgen.scenes.model import TargetModel, load_target
from scgen.scenes.spec import SceneSpec

BLENDERPROC_S = 8.4 + 1.0  # BlenderProc on this machine: 640x480 at 16 samples, plus BOP writing


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def persistent_run(generator: Generator, specs: list[SceneSpec], quality: str) -> dict:
    """Render, annotate and write every spec with one backend; per-frame times and RSS."""
    backend = BlenderBackend(generator.model, quality=quality)
    render_s, sample_s, rss = [], [], {}
    with tempfile.TemporaryDirectory(prefix="bench-blender-") as out:
        layout = Layout(out)
        write_static_files(layout, generator)
        t_start = time.perf_counter()
        for k, spec in enumerate(specs, start=1):
            t0 = time.perf_counter()
            buffers = backend.render(spec)
            t1 = time.perf_counter()
            write_sample(layout, spec, buffers, annotate(spec, buffers), "train", WriteOptions())
            render_s.append(t1 - t0)
            sample_s.append(time.perf_counter() - t0)
            if k in (10, len(specs)):
                rss[k] = rss_mb()
            if k % 50 == 0:
                print(f"  frame {k}: RSS {rss_mb():.0f} MB", flush=True)
        total = time.perf_counter() - t_start
    cycles = backend.cycles_s
    backend.close()
    return {"render_s": render_s, "sample_s": sample_s, "total": total, "cycles": cycles, "rss": rss}


def naive_run(model: TargetModel, specs: list[SceneSpec], quality: str) -> list[float]:
    """Seconds per frame when the whole Blender scene is rebuilt for every frame."""
    times = []
    for spec in specs:
        t0 = time.perf_counter()
        backend = BlenderBackend(model, quality=quality)
        backend.render(spec)
        backend.close()
        times.append(time.perf_counter() - t0)
    return times


def foreground_psnr(rgb: np.ndarray, ref: np.ndarray, instance: np.ndarray) -> float:
    """PSNR (dB) of 8-bit sRGB over the rendered objects, dilated by 2 px to include their edges."""
    region = cv2.dilate((instance > 0).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    err = (rgb.astype(np.float64) - ref.astype(np.float64))[region]
    return float(10 * np.log10(255.0**2 / max(1e-12, float(np.mean(err**2)))))


def preset_run(model: TargetModel, specs: list[SceneSpec], ref_samples: int) -> list[tuple]:
    """(preset, seconds per frame, mean PSNR against a `ref_samples`-spp reference) per preset."""
    backend = BlenderBackend(model)
    configure_beauty(backend.scene.beauty, QualityPreset(ref_samples, 0.001, 8, 4, 4, None), gpu=False)
    refs = [backend.render(s) for s in specs]
    backend.close()
    rows = []
    for name in PRESETS:
        backend = BlenderBackend(model, quality=name)
        backend.render(specs[0])  # warm-up: first sync and kernel load
        times, psnrs = [], []
        for spec, ref in zip(specs, refs, strict=True):
            t0 = time.perf_counter()
            buffers = backend.render(spec)
            times.append(time.perf_counter() - t0)
            psnrs.append(foreground_psnr(buffers.rgb, ref.rgb, ref.instance))
        backend.close()
        rows.append((name, statistics.mean(times), statistics.mean(psnrs)))
    return rows


def report_persistent(r: dict, frames: int) -> None:
    per_sample = r["total"] / frames
    rss = ", ".join(f"after frame {k}: {v:.0f}" for k, v in r["rss"].items())
    print(f"\npersistent scene, {frames} annotated samples written in {r['total']:.1f} s")
    print(f"  images/s                       {frames / r['total']:.3f}")
    print(f"  s per annotated sample         {per_sample:.2f}")
    print(f"  median render() s              {statistics.median(r['render_s']):.2f}")
    print(f"  outside Cycles' render calls   {100 * (1 - r['cycles'] / r['total']):.1f} % of the wall time")
    print(f"  BlenderProc ({BLENDERPROC_S} s) / this  {BLENDERPROC_S / per_sample:.2f}x")
    print(f"  RSS (MB)                       {rss}")


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--naive-frames", type=int, default=5)
    ap.add_argument("--preset-frames", type=int, default=3)
    ap.add_argument("--ref-samples", type=int, default=1024)
    ap.add_argument("--quality", default="default", choices=list(PRESETS))
    ap.add_argument("--resolution", type=int, nargs=2, default=(640, 480), metavar=("W", "H"))
    ap.add_argument("--seed", type=int, default=0)
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:

    model = load_target()
    cfg = load_config(resolution=tuple(args.resolution))
    n = max(args.frames, args.naive_frames, args.preset_frames)
    generator = Generator(model, cfg, args.seed)
    specs = [generator.scene(i) for i in range(n)]
    width, height = args.resolution
    print(f"{model.name}: {len(model.mesh.faces)} triangles, {width}x{height}, {PRESETS[args.quality]}")

    if args.frames:
        r = persistent_run(generator, specs[: args.frames], args.quality)
        report_persistent(r, args.frames)
        if args.naive_frames:
            naive = statistics.mean(naive_run(model, specs[: args.naive_frames], args.quality))
            same = statistics.mean(r["render_s"][: args.naive_frames])
            print(f"\nscene rebuilt per frame (naive) vs persistent, same {args.naive_frames} scenes:")
            print(f"  naive {naive:.2f} s/frame, persistent {same:.2f} s/frame: ratio {naive / same:.2f}x")

    if args.preset_frames:
        print(f"\npresets vs a {args.ref_samples}-spp reference, {args.preset_frames} scenes:")
        print(f"  {'preset':8s} {'s/frame':>8s} {'PSNR dB':>8s}  settings")
        for name, s, psnr in preset_run(model, specs[: args.preset_frames], args.ref_samples):
            print(f"  {name:8s} {s:8.2f} {psnr:8.2f}  {PRESETS[name]}")


def main() -> None:
    run_script(run, parse_args())


if __name__ == "__main__":
    main()
