"""The camera stage on real renders: labels never depend on it, the ideal camera is the old image chain,
and a distorted, monochrome SPEED+ camera keeps every label exact through its lens."""

from __future__ import annotations

import csv
import hashlib
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
from scgen.run.runner import RenderJob, run_render
from scgen.scenes.camera_config import camera_preset
from scgen.scenes.spec import CameraSpec

BEFORE = Path(__file__).parent / "data" / "rgb_before_camera_stage.json"
# the sky and finish as they were when BEFORE was recorded (procedural Earth and stars, CAD finishes)
AS_BEFORE = {"background": {"earth_map": "procedural", "stars": "procedural"}, "finish": {"mode": "nominal"}}
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
def test_ideal_camera_reproduces_the_images_from_before_the_stage(backend: str):
    """Byte for byte, except `complex` backgrounds, whose sun glare became the stage's flare."""
    before = json.loads(BEFORE.read_text())["samples"][backend]
    with Generator.load(seed=5, resolution=(96, 72), backend=backend, quality="draft", camera="ideal",
                        overrides=AS_BEFORE) as gen:  # fmt: skip
        for index, old in before.items():
            sample = gen.sample(int(index))
            assert sample.spec.background.kind == old["background"]
            if old["background"] != "complex":
                assert hashlib.sha256(sample.buffers.rgb.tobytes()).hexdigest() == old["rgb_sha256"], index


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
        assert rec["scene_camera"]["cam_dist"] == pytest.approx(camera_preset("speedplus")["dist"])
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
