"""Blender backend benchmark: speed per annotated sample, time outside Cycles, RSS, naive rebuild, presets,
each for the old path (Cycles traces the full frame) beside the new (only the region the objects cover).

First `--profile` samples timed by stage (Cycles' sync, BVH, path tracing, denoising, EXR; the aux
render, labels, background, camera stage, annotation, writing), each traced three ways in turn: the full
frame, one box around every object, and a box per object or group of overlapping ones (the default).
Then one worker renders `--frames` sampled scenes (640x480 by default) with one persistent backend,
annotating and writing each sample as `scgen render` does, each scene once per mode in turn (A B A B);
then `--naive-frames` of the same scenes with a backend rebuilt for every frame; then the quality
presets in both modes against a many-sample full-frame reference (PSNR over the rendered objects, so the
composited background does not inflate it); then, with `--settings-frames`, Cycles settings (samples,
adaptive sampling, the denoiser's inputs) tried one at a time on the default preset against the same
reference; with `--margin-frames`, the empty pixels traced around each box for the denoiser.

    .venv/bin/python benchmarks/bench_blender.py                      # profile, 30 frames, naive, presets
    .venv/bin/python benchmarks/bench_blender.py --frames 300 --naive-frames 0 --preset-frames 0
    .venv/bin/python benchmarks/bench_blender.py --profile 0 --frames 0 --naive-frames 0 --preset-frames 0 \
        --settings-frames 6 --ref-samples 512
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

from harness import foreground_psnr, parser, run_script

from scgen import Generator
from scgen.annotate import annotate
from scgen.dataset.layout import OBJ_ID, Layout
from scgen.dataset.writer import WriteOptions, resolved, write_sample
from scgen.render.blender.backend import BlenderBackend
from scgen.render.blender.settings import FILTER_REACH_PX, PRESETS, QualityPreset, configure_beauty
from scgen.render.objects import model_hulls
from scgen.render.region import full_frame, scene_region, traced_share
from scgen.run.runner import write_static_files
from scgen.scenes import load_config
from scgen.scenes.model import TargetModel, load_target
from scgen.scenes.spec import SceneSpec

BLENDERPROC_S = 8.4 + 1.0  # BlenderProc on this machine: 640x480 at 16 samples, plus BOP writing


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


ONE_BOX_MARGIN_PX = 16  # the one-box region path's margin for the denoiser (until the margin was measured)
MARGINS_PX = (16, 8, 4, 0)  # --margin-frames: empty pixels traced around each box for the denoiser
MODES = {"full frame": False, "region": True}  # BlenderBackend.trace_region: the old path, then the new


def persistent_run(generator: Generator, specs: list[SceneSpec], quality: str) -> dict[str, dict]:
    """Render, annotate and write every spec with one backend, once per mode in turn (A B A B, so the
    machine's drift hits both alike); per mode the per-frame times, Cycles' seconds and RSS."""
    backend = BlenderBackend(generator.model, quality=quality)
    runs = {m: {"render_s": [], "sample_s": [], "share": [], "cycles": 0.0, "rss": {}} for m in MODES}
    write = resolved(WriteOptions(), generator.cfg["camera"])  # as a run writes: the camera's format
    with tempfile.TemporaryDirectory(prefix="bench-blender-") as out:
        layouts = {m: Layout(f"{out}/{k}") for k, m in enumerate(MODES)}
        for layout in layouts.values():
            write_static_files(layout, generator)
        for k, spec in enumerate(specs, start=1):
            for mode, trace_region in MODES.items():
                r, backend.trace_region = runs[mode], trace_region
                t0, c0 = time.perf_counter(), backend.cycles_s
                buffers = backend.render(spec)
                t1 = time.perf_counter()
                write_sample(layouts[mode], spec, buffers, annotate(spec, buffers), "train", write)
                r["render_s"].append(t1 - t0)
                r["sample_s"].append(time.perf_counter() - t0)
                r["cycles"] += backend.cycles_s - c0
                r["share"].append(traced_share(backend.scene.regions))
                if k in (10, len(specs)):
                    r["rss"][k] = rss_mb()
            if k % 50 == 0:
                print(f"  frame {k}: RSS {rss_mb():.0f} MB", flush=True)
    backend.close()
    return runs


def stage_profile(generator: Generator, specs: list[SceneSpec], quality: str) -> dict[str, dict[str, float]]:
    """Median seconds per stage of one sample, per mode (A B A B). Cycles' own progress reports
    (bpy.app.handlers.render_stats) split its render calls into scene sync, BVH build, path tracing
    (denoising included) and the EXR write; denoising's share is the same beauty render again without
    the denoiser; the Python stages are timed around the backend's calls."""
    import bpy

    import scgen.render.blender.backend as blender_backend

    backend = BlenderBackend(generator.model, quality=quality, region=True)
    scene = backend.scene
    stamps: list[tuple[float, str]] = []
    bpy.app.handlers.render_stats.append(lambda stats: stamps.append((time.perf_counter(), stats)))
    hulls = model_hulls(generator.models)
    paths = {  # what each path traces: the whole frame, one box around every object with 16 px for the
        # denoiser (the region path from f325401 to c91b707; Mitsuba's, without the margin), a box per object
        # or group of overlapping objects (now)
        "full frame": lambda spec: (full_frame(spec.camera.width, spec.camera.height),),
        "one box": lambda spec: (scene_region(spec, hulls, FILTER_REACH_PX, ONE_BOX_MARGIN_PX),),
        "regions": backend.regions,
    }
    times: dict[str, dict[str, list[float]]] = {m: {} for m in paths}

    def cycles_stages(t_call: float, t_end: float) -> dict[str, float]:
        """Cycles' stages of the render calls since t_call, from its progress reports."""
        out = dict.fromkeys(("Cycles: scene sync", "Cycles: BVH", "Cycles: path tracing + denoising"), 0.0)
        marks = [(t, msg.split("|")[-1].strip()) for t, msg in stamps] + [(t_end, "end")]
        for (t0, msg), (t1, _) in zip(marks, marks[1:], strict=False):
            if msg.startswith("Sample"):
                out["Cycles: path tracing + denoising"] += t1 - t0
            elif "BVH" in msg and "Copying" not in msg:
                out["Cycles: BVH"] += t1 - t0
            elif not msg.startswith(("Finished", "Time")):
                out["Cycles: scene sync"] += t1 - t0
        out["Cycles: EXR write + read, paste"] = t_end - t_call - sum(out.values())
        return out

    def timed(stage: str, mode: str, fn, *a, **kw):
        t0 = time.perf_counter()
        result = fn(*a, **kw)
        times[mode].setdefault(stage, []).append(time.perf_counter() - t0)
        return result

    def add(mode: str, stages: dict[str, float]) -> None:
        for stage, seconds in stages.items():
            times[mode].setdefault(stage, []).append(seconds)

    write = resolved(WriteOptions(), generator.cfg["camera"])  # as a run writes: the camera's format
    with tempfile.TemporaryDirectory(prefix="bench-blender-") as out:
        layout = Layout(out)
        write_static_files(layout, generator)
        for spec in specs:
            for mode, regions_of in paths.items():
                t_sample = time.perf_counter()
                timed("scene update (matrices, props)", mode, scene.update, spec)
                regions = timed("regions", mode, regions_of, spec)
                stamps.clear()
                t0 = time.perf_counter()
                beauty = scene.render_beauty(regions)
                beauty_stages = cycles_stages(t0, time.perf_counter())
                stamps.clear()
                instance, depth = blender_backend.instance_and_depth(beauty)
                alone = blender_backend.props_may_hide_target(spec, hulls[OBJ_ID], instance, depth)
                aux_regions = backend.target_regions(spec, regions) if mode == "regions" else regions
                aux = timed("aux render (labels)", mode, scene.render_aux, alone, aux_regions)
                buffers = timed("label passes", mode, blender_backend.buffers_from_passes, spec, beauty, aux)
                background = timed("background", mode, blender_backend.background_image, spec)
                image = timed("composite", mode, blender_backend.composite, beauty, background)
                buffers.rgb, buffers.camera = timed(
                    "camera stage", mode, blender_backend.record_image, spec, image, buffers.instance
                )
                annotation = timed("annotation", mode, annotate, spec, buffers)
                timed("writing", mode, write_sample, layout, spec, buffers, annotation, "train", write)
                times[mode].setdefault("sample (total)", []).append(time.perf_counter() - t_sample)
                scene.beauty.cycles.use_denoising = False
                t0 = time.perf_counter()
                scene.render_beauty(regions)
                plain = cycles_stages(t0, time.perf_counter())["Cycles: path tracing + denoising"]
                scene.beauty.cycles.use_denoising = PRESETS[quality].denoise_quality is not None
                stamps.clear()
                denoise = beauty_stages["Cycles: path tracing + denoising"] - plain
                add(
                    mode,
                    {**{f"beauty {k}": v for k, v in beauty_stages.items()}, "of which denoising": denoise},
                )
                add(
                    mode,
                    {
                        "pixels traced (share of frame)": traced_share(regions),
                        "render calls per pass": len(regions),
                    },
                )
    backend.close()
    return {m: {stage: statistics.median(v) for stage, v in t.items()} for m, t in times.items()}


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


def scored_render(backend: BlenderBackend, spec: SceneSpec, ref) -> tuple[float, float]:
    """(seconds, PSNR over the objects against `ref`) of one render of `spec`."""
    t0 = time.perf_counter()
    buffers = backend.render(spec)
    seconds = time.perf_counter() - t0
    return seconds, foreground_psnr(buffers.rgb, ref.rgb, ref.instance)


def references(model: TargetModel, specs: list[SceneSpec], ref_samples: int) -> list:
    """Each spec rendered full frame with `ref_samples` samples, no denoiser: the quality reference."""
    backend = BlenderBackend(model, region=False)
    configure_beauty(backend.scene.beauty, QualityPreset(ref_samples, 0.001, 8, 4, 4, None), gpu=False)
    refs = [backend.render(s) for s in specs]
    backend.close()
    return refs


def preset_run(model: TargetModel, specs: list[SceneSpec], refs: list) -> list[tuple]:
    """(preset, mode, seconds per frame, mean PSNR against the references) per preset and mode, the modes
    in turn on each scene."""
    rows = []
    for name in PRESETS:
        backend = BlenderBackend(model, quality=name)
        backend.render(specs[0])  # warm-up: first sync and kernel load
        times: dict[str, list[float]] = {m: [] for m in MODES}
        psnrs: dict[str, list[float]] = {m: [] for m in MODES}
        for spec, ref in zip(specs, refs, strict=True):
            for mode, trace_region in MODES.items():
                backend.trace_region = trace_region
                seconds, psnr = scored_render(backend, spec, ref)
                times[mode].append(seconds)
                psnrs[mode].append(psnr)
        backend.close()
        rows += [(name, m, statistics.mean(times[m]), statistics.mean(psnrs[m])) for m in MODES]
    return rows


# Cycles settings tried against the default preset's (scene.cycles attributes). Each runs on a backend of
# its own, set before its first render: a live Cycles session keeps the sample count it was made with,
# and a later change of `samples` alone is not seen until something else makes Cycles start a new one.
SETTINGS = {
    "default preset": {},
    "no adaptive sampling": {"use_adaptive_sampling": False},
    "adaptive: min 4 samples, threshold 0.05": {"adaptive_min_samples": 4, "adaptive_threshold": 0.05},
    "OIDN prefilter NONE": {"denoising_prefilter": "NONE"},
    "OIDN albedo only": {"denoising_input_passes": "RGB_ALBEDO"},
    "no denoiser": {"use_denoising": False},
    "8 samples": {"samples": 8},
    "10 samples": {"samples": 10},
    "16 samples": {"samples": 16},
    "24 samples": {"samples": 24},
    # bounces and lights (the default preset: 3 bounces, 1 diffuse, 2 glossy; the light tree)
    "max bounces 2, glossy 1": {"max_bounces": 2, "glossy_bounces": 1},
    "max bounces 1": {"max_bounces": 1, "glossy_bounces": 1},
    "glossy bounces 1": {"glossy_bounces": 1},
    "diffuse bounces 0": {"diffuse_bounces": 0},
    "light tree off": {"use_light_tree": False},
    "light tree off, 16 samples (the preset before 2026-12-07)": {"use_light_tree": False, "samples": 16},
    "light threshold 0 (no culling)": {"light_sampling_threshold": 0.0},
    "fast GI (AO after 1 bounce)": {"use_fast_gi": True, "ao_bounces_render": 1},
}


def settings_run(model: TargetModel, specs: list[SceneSpec], refs: list, threads: int) -> list[tuple]:
    """(settings, seconds per render, mean PSNR against the references) for each of SETTINGS applied to
    the default preset, the region path, one backend each with `threads` render threads."""
    rows = []
    for name, settings in SETTINGS.items():
        backend = BlenderBackend(model, threads=threads)
        for key, value in settings.items():
            setattr(backend.scene.beauty.cycles, key, value)
        backend.render(specs[0])  # warm-up: first sync and kernel load
        times, psnrs = [], []
        for spec, ref in zip(specs, refs, strict=True):
            seconds, psnr = scored_render(backend, spec, ref)
            times.append(seconds)
            psnrs.append(psnr)
        backend.close()
        rows.append((name, statistics.mean(times), statistics.mean(psnrs)))
    return rows


def margin_run(model: TargetModel, specs: list[SceneSpec], refs: list) -> list[tuple]:
    """(margin in px, seconds per render, mean PSNR against the references, mean share of the frame
    traced) for the full frame (margin None) and each of MARGINS_PX, the margins in turn on each scene."""
    backend = BlenderBackend(model)
    backend.render(specs[0])  # warm-up: first sync and kernel load
    margins = (None, *MARGINS_PX)
    runs: dict = {m: ([], [], []) for m in margins}
    for spec, ref in zip(specs, refs, strict=True):
        for margin in margins:
            backend.trace_region = margin is not None
            backend.margin_px = margin or 0
            seconds, psnr = scored_render(backend, spec, ref)
            times, psnrs, shares = runs[margin]
            times.append(seconds)
            psnrs.append(psnr)
            shares.append(traced_share(backend.scene.regions))
    backend.close()
    return [(m, *(statistics.mean(v) for v in runs[m])) for m in margins]


def report_persistent(runs: dict[str, dict], frames: int) -> None:
    """The modes side by side: seconds per annotated sample (render, annotate, write) and what they give."""
    names, mean, median = list(runs), statistics.mean, statistics.median
    print(f"\npersistent scene, {frames} annotated samples per mode, the modes in turn (A B A B), one worker")
    print(f"  {'':34s}" + "".join(f"{n:>12s}" for n in names))

    def row(label: str, fmt: str, value) -> None:
        print(f"  {label:34s}" + "".join(f"{value(runs[n]):12{fmt}}" for n in names))

    row("s per annotated sample (mean)", ".3f", lambda r: mean(r["sample_s"]))
    row("s per annotated sample (median)", ".3f", lambda r: median(r["sample_s"]))
    row("median render() s", ".3f", lambda r: median(r["render_s"]))
    row("images/s", ".3f", lambda r: 1 / mean(r["sample_s"]))
    row("outside Cycles' render calls %", ".1f", lambda r: 100 * (1 - r["cycles"] / sum(r["sample_s"])))
    row("pixels traced, median share %", ".1f", lambda r: 100 * median(r["share"]))
    row(f"BlenderProc ({BLENDERPROC_S} s) / this", ".2f", lambda r: BLENDERPROC_S / mean(r["sample_s"]))
    full, region = (mean(runs[n]["sample_s"]) for n in names)
    print(f"  region / full frame: {region / full:.3f} of the time per sample")
    for n in names:
        rss = ", ".join(f"after frame {k}: {v:.0f}" for k, v in runs[n]["rss"].items())
        print(f"  RSS (MB), {n}: {rss}")


def report_profile(profile: dict[str, dict[str, float]], n: int) -> None:
    names = list(profile)
    print(f"\nstages of one sample, median of {n} samples per mode (A B A B), seconds")
    print(f"  {'stage':40s}" + "".join(f"{m:>12s}" for m in names))
    for stage in profile[names[0]]:
        print(f"  {stage:40s}" + "".join(f"{profile[m][stage]:12.3f}" for m in names))


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--profile", type=int, default=3, help="samples profiled by stage (0: none)")
    ap.add_argument("--naive-frames", type=int, default=5)
    ap.add_argument("--preset-frames", type=int, default=3)
    ap.add_argument("--settings-frames", type=int, default=0, help="scenes for the Cycles settings sweep")
    ap.add_argument("--settings-threads", type=int, default=1, help="render threads in the settings sweep")
    ap.add_argument("--margin-frames", type=int, default=0, help="scenes for the denoiser-margin sweep")
    ap.add_argument("--ref-samples", type=int, default=1024)
    ap.add_argument("--quality", default="default", choices=list(PRESETS))
    ap.add_argument("--resolution", type=int, nargs=2, default=(640, 480), metavar=("W", "H"))
    ap.add_argument("--seed", type=int, default=0)
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:

    model = load_target()
    cfg = load_config(resolution=tuple(args.resolution))
    n = max(args.frames, args.naive_frames, args.preset_frames, args.settings_frames, args.margin_frames,
            args.profile)  # fmt: skip
    generator = Generator(model, cfg, args.seed)
    specs = [generator.scene(i) for i in range(n)]
    width, height = args.resolution
    print(f"{model.name}: {len(model.mesh.faces)} triangles, {width}x{height}, {PRESETS[args.quality]}")

    if args.profile:
        report_profile(stage_profile(generator, specs[: args.profile], args.quality), args.profile)

    if args.frames:
        runs = persistent_run(generator, specs[: args.frames], args.quality)
        report_persistent(runs, args.frames)
        if args.naive_frames:
            naive = statistics.mean(naive_run(model, specs[: args.naive_frames], args.quality))
            same = statistics.mean(runs["region"]["render_s"][: args.naive_frames])
            print(f"\nscene rebuilt per frame (naive) vs persistent, same {args.naive_frames} scenes:")
            print(f"  naive {naive:.2f} s/frame, persistent {same:.2f} s/frame: ratio {naive / same:.2f}x")

    if args.preset_frames:
        refs = references(model, specs[: args.preset_frames], args.ref_samples)
        print(f"\npresets vs a {args.ref_samples}-spp reference, {args.preset_frames} scenes:")
        print(f"  {'preset':8s} {'mode':>10s} {'s/frame':>8s} {'PSNR dB':>8s}  settings")
        for name, mode, s, psnr in preset_run(model, specs[: args.preset_frames], refs):
            print(f"  {name:8s} {mode:>10s} {s:8.2f} {psnr:8.2f}  {PRESETS[name]}")

    if args.settings_frames:
        chosen = specs[: args.settings_frames]
        refs = references(model, chosen, args.ref_samples)
        threads, n_ref = args.settings_threads, args.ref_samples
        print(f"\nCycles settings on the default preset, region path, {threads} thread(s), vs a {n_ref}-spp "
              f"reference, {args.settings_frames} scenes:")  # fmt: skip
        print(f"  {'settings':58s} {'s/render':>9s} {'PSNR dB':>8s}")
        for name, s, psnr in settings_run(model, chosen, refs, args.settings_threads):
            print(f"  {name:58s} {s:9.3f} {psnr:8.2f}")

    if args.margin_frames:
        chosen = specs[: args.margin_frames]
        refs = references(model, chosen, args.ref_samples)
        print(f"\ndenoiser margin around each box, default preset, vs a {args.ref_samples}-spp reference, "
              f"{args.margin_frames} scenes, the margins in turn:")  # fmt: skip
        print(f"  {'margin':>12s} {'s/render':>9s} {'PSNR dB':>8s} {'traced':>7s}")
        for margin, s, psnr, share in margin_run(model, chosen, refs):
            label = "full frame" if margin is None else f"{margin} px"
            print(f"  {label:>12s} {s:9.3f} {psnr:8.2f} {100 * share:6.1f}%")


if __name__ == "__main__":
    run_script(run, parse_args())
