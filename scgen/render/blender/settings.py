"""Cycles settings: the quality presets, the beauty render and the one-sample aux render.

Cycles writes the depth, object index and position passes from the first camera sample of each
pixel only, and shoots that sample through the pixel centre whatever the pixel filter (kernel
integrator/init_from_camera.h: `rand_filter = (sample == 0) ? (0.5, 0.5) : ...`; checked against
Mitsuba's ray casts in tests/test_blender_geometry.py). So the beauty render keeps its
anti-aliasing filter, adaptive sampling and denoiser and still yields exact pixel-centre labels.
Normals are accumulated over all samples (blended at edges), hence the one-sample aux render.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from scgen.render.conventions import check_quality


@dataclass(frozen=True)
class QualityPreset:
    """Samples per pixel, adaptive-sampling noise threshold, bounce limits and OIDN settings (None: off)."""

    samples: int
    noise_threshold: float
    max_bounces: int
    diffuse_bounces: int
    glossy_bounces: int
    denoise_quality: str | None  # OIDN "FAST" | "BALANCED" | "HIGH"
    denoise_prefilter: str = "FAST"  # OIDN albedo/normal prefilter: "NONE" | "FAST" | "ACCURATE"


# Chosen by PSNR against a 1024-spp reference per second (benchmarks/bench_blender.py, 640x480,
# 2 CPU cores): OIDN FAST is the best buy from 8 spp up; OIDN HIGH/ACCURATE costs ~5 s a frame on
# CPU for < 1 dB over BALANCED; fewer bounces save no measurable time on this scene. The default's 12
# samples with the light tree (configure_common) give 0.35 dB more over the objects than BlenderProc's 16
# without it, in 8 % less time (12 scenes against 512 spp, docs/benchmarks.md, "Cycles' settings").
PRESETS = {
    "draft": QualityPreset(8, 0.05, 2, 1, 1, denoise_quality=None),
    "default": QualityPreset(12, 0.02, 3, 1, 2, denoise_quality="FAST"),
    "high": QualityPreset(64, 0.01, 4, 2, 2, denoise_quality="BALANCED"),
}
FILTER_WIDTH_PX = 1.5  # the beauty render's Blackman-Harris filter width
# How far from its pixel's centre a sample lands: the whole width, not half of it. Cycles builds a
# Blackman-Harris filter's importance table over twice the width it is given (scene/film.cpp,
# filter_table: `width *= 2.0f`), so samples reach +-1.5 px; seen in a render, a pixel 1.16 px from a
# truss's projected box took a sample from it (tests/test_blender_region.py, the occluder case)
FILTER_REACH_PX = FILTER_WIDTH_PX
SUN_ANGLE_RAD = 0.00925  # 0.53 degrees: the Sun's disc at 1 AU, so shadows stay hard


def preset(quality: str) -> QualityPreset:
    check_quality(quality)
    return PRESETS[quality]


def configure_common(scene: Any, gpu: bool, threads: int | None, exr_path: str) -> None:
    """Engine, device, CPU threads (None: all cores), transparent film, persistent data, EXR output."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "GPU" if gpu else "CPU"
    scene.render.threads_mode = "AUTO" if threads is None else "FIXED"
    if threads is not None:
        scene.render.threads = threads
    scene.render.use_persistent_data = True  # keep the synced scene and BVH between frames
    scene.render.film_transparent = True  # backgrounds are composited in numpy, as for Mitsuba
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
    scene.render.resolution_percentage = 100
    scene.cycles.sample_offset = 0  # the centred sample 0, source of the label passes, must be rendered
    # the light tree samples the sun and the Earth's or Moon's light by what each may give the shading
    # point: +1.4 dB over the objects at 16 spp for 7 % more time (docs/benchmarks.md, "Cycles' settings")
    scene.cycles.use_light_tree = True
    scene.cycles.caustics_reflective = scene.cycles.caustics_refractive = False
    scene.cycles.transmission_bounces = scene.cycles.volume_bounces = 0
    scene.cycles.transparent_max_bounces = 0
    settings = scene.render.image_settings
    settings.media_type = "MULTI_LAYER_IMAGE"  # Blender 5.0: before file_format, else refused
    settings.file_format = "OPEN_EXR_MULTILAYER"
    settings.color_depth = "32"
    settings.exr_codec = "NONE"  # written to and read from a RAM folder: compression only costs time
    scene.render.filepath = exr_path


def configure_beauty(scene: Any, quality: QualityPreset, gpu: bool) -> None:
    """The RGB render: anti-aliased, adaptive, denoised per the preset; depth and object index passes."""
    c = scene.cycles
    c.samples = quality.samples
    c.use_adaptive_sampling = True
    c.adaptive_threshold = quality.noise_threshold
    c.max_bounces = quality.max_bounces
    c.diffuse_bounces = quality.diffuse_bounces
    c.glossy_bounces = quality.glossy_bounces
    c.pixel_filter_type = "BLACKMAN_HARRIS"
    c.filter_width = FILTER_WIDTH_PX
    c.use_denoising = quality.denoise_quality is not None
    if quality.denoise_quality is not None:
        c.denoiser = "OPENIMAGEDENOISE"
        c.denoising_input_passes = "RGB_ALBEDO_NORMAL"
        c.denoising_quality = quality.denoise_quality
        c.denoising_prefilter = quality.denoise_prefilter
        c.denoising_use_gpu = gpu
    layer = scene.view_layers[0]
    layer.use_pass_z = layer.use_pass_object_index = True


def configure_aux(scene: Any) -> None:
    """The label render: one centred sample, direct light only, no denoising."""
    c = scene.cycles
    c.samples = 1
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = 0
