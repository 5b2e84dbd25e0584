"""The JPEG twin of a PNG dataset (benchmarks/jpeg_twin.py) is what a `--rgb-format jpg` render writes."""

from __future__ import annotations

import sys
from pathlib import Path

from conftest import render_dataset

from scgen.dataset.writer import WriteOptions

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from jpeg_twin import make_twin  # noqa: E402

N = 4
PNG = WriteOptions(rgb_format="png")


def test_twin_images_are_the_jpg_render_byte_for_byte_and_labels_are_the_same_files(tmp_path: Path):
    png = render_dataset(tmp_path / "png", n=N, write=PNG)
    jpg = render_dataset(tmp_path / "jpg", n=N, write=WriteOptions(rgb_format="jpg"))
    twin = tmp_path / "twin"
    assert make_twin(png, twin, ["train", "val", "test"], for_training=False) == N
    rendered = sorted(p.relative_to(jpg) for p in jpg.rglob("rgb/*.jpg"))
    assert len(rendered) == N and sorted(p.relative_to(twin) for p in twin.rglob("rgb/*")) == rendered
    for rel in rendered:
        assert (twin / rel).read_bytes() == (jpg / rel).read_bytes(), rel
    for kind in ("mask", "mask_visib", "xyz", "depth", "records"):
        files = sorted(png.rglob(f"{kind}/*"))
        assert files and all((twin / p.relative_to(png)).samefile(p) for p in files), kind


def test_for_training_keeps_what_posenet_reads(tmp_path: Path):
    png = render_dataset(tmp_path / "png", n=N, write=PNG)
    twin = tmp_path / "twin"
    make_twin(png, twin, ["train", "test"], for_training=True)
    kinds = {p.parent.name for p in twin.rglob("*") if p.is_file()}
    assert not kinds & {"depth", "records", "models_eval"} and not (twin / "val").exists()
    assert not (twin / "metadata.csv").exists() and (twin / "models" / "models_info.json").is_file()
    for split in ("train", "test"):
        labels = {p.parent.name for p in (twin / split).rglob("*") if p.is_file()}
        assert ({"xyz", "mask", "mask_visib"} <= labels) == (split == "train"), (split, labels)
        assert "rgb" in labels
