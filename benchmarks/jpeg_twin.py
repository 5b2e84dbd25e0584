"""A PNG dataset's JPEG twin: the same samples as `scgen render --rgb-format jpg` would have written them.

    python benchmarks/jpeg_twin.py DATA OUT [--splits train test] [--for-training]

DATA: a dataset of PNG images (`scgen render --rgb-format png`, or `--camera ideal`).

Every sample's RGB is re-encoded from its lossless PNG with the writer's own encoder
(scgen.dataset.writer.encode_rgb) at the JPEG quality its record drew (`camera.output.jpeg_quality`), so
the twin's images are byte for byte those of a `--rgb-format jpg` render of the same seed; every other
file is hard-linked (copied across file systems). Training one recipe on DATA and on OUT measures what
the format costs the network (issue 41: the default format decided by measurement).

--for-training keeps only what `posenet train` (on the train split) and `posenet eval` (on the others)
read: it leaves out depth/, records/, models_eval/ and metadata.csv, and outside the train split the xyz
maps and masks; for sending a set to a training node as one small archive.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
from pathlib import Path

from harness import parser, run_script
from tqdm import tqdm

from scgen.dataset.layout import Layout, open_dataset
from scgen.dataset.writer import drawn_jpeg_quality, encode_rgb
from scgen.errors import ScgenError
from scgen.io.atomic import atomic_write_bytes
from scgen.io.bop import split_names
from scgen.io.image_file import read_image
from scgen.scenes.spec import SceneSpec

POSENET_SKIPS = {"depth", "records", "models_eval", "metadata.csv"}  # what posenet never opens
LABELS_FOR_TRAINING = {"xyz", "mask", "mask_visib"}  # what posenet reads of the train split alone


def link_or_copy(src: Path, dst: Path) -> None:
    dst.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def make_twin(data: Path, out: Path, splits: list[str], for_training: bool) -> int:
    """Writes OUT; returns the number of images re-encoded."""
    layout, manifest = open_dataset(data)
    if manifest["rgb_format"] != "png":
        raise ScgenError(f"{data} holds {manifest['rgb_format']} images, not PNG")
    twin = Layout(out)
    skips = POSENET_SKIPS if for_training else set()
    left_out = set(split_names(data)) - set(splits)
    for src in sorted(data.rglob("*")):
        rel = src.relative_to(data)
        top = rel.parts[0]
        if src.is_dir() or skips & set(rel.parts) or rel.parent.name == "rgb":
            continue
        if for_training and top != "train" and LABELS_FOR_TRAINING & set(rel.parts):
            continue
        if top in left_out:
            continue
        link_or_copy(src, out / rel)
    records = [p for p in layout.record_paths() if p.parts[-4] in splits]
    for path in tqdm(records, desc="jpeg twin", unit="img"):
        record = json.loads(path.read_text())
        split, sid = record["split"], record["sample_id"]
        quality = drawn_jpeg_quality(SceneSpec.from_dict(record["spec"]))
        image = read_image(layout.rgb(split, sid))  # OpenCV's channel order; encode_rgb takes RGB
        rgb = image[..., ::-1] if image.ndim == 3 else image
        target = twin.rgb(split, sid, "jpg")
        target.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(target, encode_rgb(rgb, "jpg", quality))
    return len(records)


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("data", type=Path, help="A PNG dataset (scgen render --rgb-format png).")
    ap.add_argument("out", type=Path, help="The twin's folder (must not exist).")
    ap.add_argument("--splits", nargs="+", default=["train", "val", "test"], help="Splits to carry over.")
    ap.add_argument("--for-training", action="store_true", help="Only what posenet reads.")
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    if args.out.exists():
        raise ScgenError(f"{args.out} exists")
    n = make_twin(args.data, args.out, args.splits, args.for_training)
    print(f"wrote {args.out}: {n} images as JPEG at their drawn quality")


if __name__ == "__main__":
    run_script(run, parse_args())
