"""The camera stage on real renders: labels never depend on it, the ideal camera is the old image chain,
and a distorted, monochrome SPEED+ camera keeps every label exact through its lens."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from posenet.data.layout import scan_split
from posenet.errors import PosenetError
from scgen.cli import main
from scgen.dataset.layout import Layout
from scgen.dataset.validate import reprojection_error, validate_dataset
from scgen.dataset.writer import rgb_format_for
from scgen.errors import ScgenError
from scgen.generator import Generator
from scgen.io import bop
from scgen.io.exr import read_xyz_exr
from scgen.render.region import FULL_FRAME_ENV
from scgen.run.runner import RenderJob, run_render
from scgen.scenes.config.camera import camera_preset
from scgen.scenes.spec import CameraSpec

BEFORE = Path(__file__).parent / "data" / "rgb_before_camera_stage.json"  # its images: BEFORE's folder
# the sky and finish as they were when BEFORE was recorded (procedural Earth and stars, CAD finishes)
AS_BEFORE = {"background": {"earth_map": "procedural", "stars": "procedural"}, "finish": {"mode": "nominal"}}
# What rendered floats may move between x86-64 CPU families (Embree's and Dr.Jit's kernels differ by ISA: FMA,
# packet width, rsqrt approximations). Widespread last-bit rounding moves many pixels by a code or two: the
# mean bound. A ray that lands on the other side of an edge, or a sampling decision that flips, moves one of
# draft quality's 4 samples, up to 64 codes in that pixel alone: the count bound (20 of 6,912 pixels; a
# float-level change of the shadow rays' ends once moved 8 pixels by at most 28 codes). Either bound
# refuses what the camera stage could get wrong: a 1/3-stop exposure, sigma-1 noise, a one-pixel shift,
# a 5 % gain (test_the_render_tolerance_refuses_what_a_camera_could_change).
MEAN_ABS_DN = 0.2
FAR_DN, FAR_SHARE = 2, 0.003


def render_mismatch(image: np.ndarray, reference: np.ndarray) -> str | None:
    """Why `image` is not `reference` up to cross-CPU float noise (see MEAN_ABS_DN), or None."""
    if image.shape != reference.shape:
        return f"shape {image.shape}, not {reference.shape}"
    diff = np.abs(image.astype(np.int16) - reference.astype(np.int16))
    far = float((diff.max(axis=-1) > FAR_DN).mean())
    if diff.mean() > MEAN_ABS_DN or far > FAR_SHARE:
        return f"mean |diff| {diff.mean():.3f} DN, {far:.2%} of pixels off by more than {FAR_DN} DN"
    return None


def _before_images(backend: str) -> dict[int, tuple[str, np.ndarray | None]]:
    """BEFORE's samples of `backend`: index -> (background kind, the recorded RGB image or None)."""
    entries = json.loads(BEFORE.read_text())["samples"][backend]
    folder = BEFORE.with_suffix("")
    return {
        int(index): (old["background"], old["image"] and cv2.imread(str(folder / old["image"]))[..., ::-1])
        for index, old in entries.items()
    }


LABEL_DIRS = ("mask", "mask_visib", "xyz", "depth")


def _render(out: Path, n: int, camera: str, resolution: tuple[int, int], backend: str = "mitsuba") -> Path:
    job = RenderJob(out=out, n=n, seed=9, backend=backend, quality="draft", resolution=resolution,
                    camera=camera)  # fmt: skip
    run_render(job, progress=False)
    return out


def _metadata(root: Path) -> list[dict[str, str]]:
    with open(root / "metadata.csv") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize("backend", ["mitsuba", "blender"])
def test_ideal_camera_reproduces_the_images_from_before_the_stage(
    backend: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Up to cross-CPU float noise, except `complex` backgrounds, whose sun glare became the stage's flare
    (Mitsuba's images were made again when its film took a tent filter: the JSON's provenance).
    Traced over the whole frame, as the stored images were; the region renders are held to the full frame
    by tests/test_blender_region.py and tests/test_mitsuba_region.py (Mitsuba's sampler seeds by wavefront
    lane, not by pixel, so its window is another draw of the same noise, not these pixels)."""
    monkeypatch.setenv(FULL_FRAME_ENV, "1")
    before = _before_images(backend)
    with Generator.load(seed=5, resolution=(96, 72), backend=backend, quality="draft", camera="ideal",
                        overrides=AS_BEFORE) as gen:  # fmt: skip
        for index, (background, image) in before.items():
            sample = gen.sample(index)
            assert sample.spec.background.kind == background
            if background != "complex":
                assert render_mismatch(sample.buffers.rgb, image) is None, (index, render_mismatch(
                    sample.buffers.rgb, image))  # fmt: skip


def test_the_render_tolerance_refuses_what_a_camera_could_change():
    """The bounds admit a few pixels flipped by a whole sample, and refuse each change the camera stage could
    make, on every stored image (the dark `clean` one, 1 % lit, is the hardest to tell)."""
    rng = np.random.default_rng(0)
    for backend in ("mitsuba", "blender"):
        for index, (_, image) in _before_images(backend).items():
            if image is None:
                continue
            linear = (image / 255.0) ** 2.2
            flipped = image.copy()
            flipped.reshape(-1, 3)[rng.choice(image.shape[0] * image.shape[1], 20, replace=False)] ^= 64
            assert render_mismatch(flipped, image) is None, (backend, index)
            changed = {
                "1/3 stop": 255 * np.clip(linear * 2 ** (1 / 3), 0, 1) ** (1 / 2.2),
                "noise": image + rng.normal(0.0, 1.0, image.shape),
                "shift": np.roll(image, 1, axis=1),
                "gain": image * 1.05,
            }
            for what, other in changed.items():
                other = np.clip(np.round(other), 0, 255).astype(np.uint8)
                assert render_mismatch(other, image) is not None, (backend, index, what)


def test_labels_are_byte_identical_whatever_the_camera(tmp_path: Path):
    ideal = _render(tmp_path / "ideal", 4, "ideal", (96, 72))
    default = _render(tmp_path / "default", 4, "default", (96, 72))
    label_files = [p.relative_to(ideal) for p in ideal.rglob("*") if p.parent.name in LABEL_DIRS]
    assert len(label_files) >= 12
    for rel in label_files:
        assert (ideal / rel).read_bytes() == (default / rel).read_bytes(), rel
    for name in bop.SCENE_FILES:
        for chunk in (ideal / "train").iterdir():
            a, b = (bop.read_json(root / "train" / chunk.name / f"{name}.json") for root in (ideal, default))
            if name == "scene_camera":  # the exposure is the camera's: all else is the same
                a = {k: {**v, "exposure_ev": 0} for k, v in a.items()}
                b = {k: {**v, "exposure_ev": 0} for k, v in b.items()}
            assert a == b
    assert {r["noise"] for r in _metadata(ideal)} == {"none"}
    assert {r["noise"] for r in _metadata(default)} <= {"low", "medium", "high"}
    # --rgb-format auto: the ideal camera's exact pixels as PNG, the sensor's noisy ones as JPEG
    assert [bop.read_json(r / "scgen.json")["rgb_format"] for r in (ideal, default)] == ["png", "jpg"]
    images = [cv2.imread(str(p)) for p in sorted(ideal.rglob("rgb/*.png"))]
    noisy = [cv2.imread(str(p)) for p in sorted(default.rglob("rgb/*.jpg"))]
    assert all((a != b).any() for a, b in zip(images, noisy, strict=True))  # the stage did act


@pytest.mark.parametrize("backend", ["mitsuba", "blender"])
def test_speedplus_camera_keeps_labels_exact_through_its_lens(tmp_path: Path, backend: str):
    root = _render(tmp_path / "sp", 2, "speedplus", (480, 300), backend)
    problems, n = validate_dataset(root, progress=False)
    assert problems == [] and n == 2
    layout = Layout(root)
    for rec in map(bop.read_json, layout.record_paths()):
        # the preset's coefficients copied as floats into the spec and the JSON (repr): the same floats
        assert rec["scene_camera"]["cam_dist"] == list(camera_preset("speedplus")["dist"])
        image = cv2.imread(str(layout.rgb(rec["split"], rec["sample_id"], "jpg")), cv2.IMREAD_UNCHANGED)
        assert image.shape == (300, 480) and image.dtype == np.uint8  # monochrome, as SPEED+
        info = rec["scene_gt_info"][0]
        if info["xyz_box"] is None:
            continue
        x, y, w, h = info["xyz_box"]
        crop = read_xyz_exr(layout.xyz(rec["split"], rec["sample_id"]))
        vs, us = np.nonzero(np.abs(crop).max(axis=-1) > 0)
        R, t = bop.gt_pose(rec["scene_gt"][0])
        lens = CameraSpec.from_scene_camera(rec["scene_camera"], 480, 300)
        pinhole = CameraSpec.from_scene_camera({"cam_K": rec["scene_camera"]["cam_K"]}, 480, 300)
        C = crop[vs, us].astype(np.float64)
        through_lens = reprojection_error(C, us + x, vs + y, lens, R, t)
        without = reprojection_error(C, us + x, vs + y, pinhole, R, t)
        assert np.quantile(through_lens, 0.995) < 0.5  # exact through the lens...
        assert np.median(without) > 10 * np.median(through_lens)  # ...and the lens matters
    with pytest.raises(PosenetError, match="distortion"):  # posenet's geometry is pinhole: it says so
        scan_split(root, rec["split"], 1)


def test_jpeg_with_16_bit_output_is_refused_before_anything_is_written(tmp_path: Path):
    config = tmp_path / "deep.toml"
    config.write_text("[camera.output]\nbits = 16\n")
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["render", "--n", "1", "--out", str(out), "--backend", "mitsuba",
                                       "--config", str(config), "--rgb-format", "jpg"])  # fmt: skip
    assert result.exit_code != 0 and "camera.output.bits" in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert not out.exists()


def test_auto_format_is_jpeg_for_a_camera_with_a_sensor_and_png_for_exact_images():
    deep = camera_preset("default")
    deep["output"]["bits"] = 16
    assert [
        rgb_format_for("auto", camera_preset(name)) for name in ("default", "ccd", "speedplus", "ideal")
    ] == ["jpg", "jpg", "jpg", "png"]
    assert rgb_format_for("auto", deep) == "png" and rgb_format_for("png", camera_preset("default")) == "png"
    assert rgb_format_for("jpg", camera_preset("ideal")) == "jpg"  # asked for: an exact image, compressed
    for requested, camera in (("jpg", deep), ("tiff", camera_preset("default"))):
        with pytest.raises(ScgenError):
            rgb_format_for(requested, camera)


def test_unknown_camera_preset_is_one_line(tmp_path: Path):
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["render", "--n", "1", "--out", str(out), "--camera", "gopro"])
    assert result.exit_code != 0 and "unknown camera preset 'gopro'" in result.output
    assert not out.exists()
