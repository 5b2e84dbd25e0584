"""How much of a detector's box error is target the image does not show (self-shadow on a black sky).

    python benchmarks/probes/unseen_pixels.py --data DIR [--split test --boxes det_test.json] ...

On the split's images with a clean (star-field) background, a target pixel is shown when it is brighter
than the sky around it: its luminance above the median of the pixels outside the full mask plus 6 of their
standard deviations (1.4826 x MAD, so that stars do not count) plus 1 DN. The box of the shown visible
pixels is what a detector that boxes exactly what it sees would give; its IoU loss (1 - IoU) against the
box the detector learns (`bbox_obj` clipped to the image) is the loss no detector can avoid without a
prior on the shape. Printed per split and together: the images, the share of visible pixels shown, that
loss and, with a --boxes file per --split (as `posenet boxes --detector` writes it), the detector's own
IoU loss and the share of it the unseen pixels explain.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import parser, run_script

from posenet.data.boxes import clip_box, read_boxes
from posenet.data.io import read_bgr, read_mask
from posenet.data.layout import Instance, scan_split
from posenet.evaluation.evaluate import format_table
from posenet.predict.recrop import box_iou
from scgen.annotate.annotate import mask_bbox
from scgen.dataset.layout import read_metadata

NOISE_SIGMAS = 6.0  # the sky's noise a shown pixel stands above
MAD_TO_SIGMA = 1.4826  # a Gaussian's standard deviation per median absolute deviation
BGR_LUMA = np.array([0.114, 0.587, 0.299], np.float32)  # Rec. 601 weights, in OpenCV's channel order


def shown_pixels(inst: Instance) -> tuple[np.ndarray, np.ndarray]:
    """(visible mask, the visible pixels brighter than the sky's noise floor) of an instance."""
    luma = read_bgr(inst.rgb).astype(np.float32) @ BGR_LUMA
    visible, full = read_mask(inst.mask_visib) > 0, read_mask(inst.mask) > 0
    sky = luma[~full]
    median = float(np.median(sky))
    floor = median + NOISE_SIGMAS * MAD_TO_SIGMA * float(np.median(np.abs(sky - median))) + 1.0
    return visible, visible & (luma > floor)


def clean_sky(data: Path) -> set[tuple[int, int]]:
    """The (scene_id, im_id) of the dataset's images with a clean (star-field) background."""
    rows = read_metadata(data)
    return {(int(r["scene_id"]), int(r["im_id"])) for r in rows if r["background"] == "clean"}


def split_rows(data: Path, split: str, boxes: Path | None, obj_id: int) -> list[tuple[float, ...]]:
    """Per clean-sky instance of `split`: (share of visible pixels shown, unseen loss, detector's loss
    (nan without `boxes`))."""
    clean = clean_sky(data)
    detected = read_boxes(boxes, obj_id) if boxes is not None else {}
    rows = []
    for inst in scan_split(data, split, obj_id):
        target = clip_box(inst.bbox_obj, inst.image_size)
        if inst.key not in clean or inst.px_count_visib == 0 or target is None:
            continue
        visible, shown = shown_pixels(inst)
        unseen = 1.0 - box_iou(tuple(mask_bbox(shown)), target)  # no pixel shown: an empty box, IoU 0
        det = detected.get(inst.key)
        own = 1.0 - box_iou(det, target) if isinstance(det, tuple) else (1.0 if boxes is not None else np.nan)
        rows.append((shown.sum() / visible.sum(), unseen, own))
    return rows


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--data", type=Path, required=True, help="A scgen dataset.")
    ap.add_argument("--split", action="append", help="A split to measure (repeatable) [test].")
    ap.add_argument("--boxes", type=Path, action="append", help="A detector's box file per --split, in turn.")
    ap.add_argument("--obj-id", type=int, default=1, help="[1]")
    args = ap.parse_args()
    args.split = args.split or ["test"]
    if args.boxes is not None and len(args.boxes) != len(args.split):
        ap.error(f"give one --boxes per --split: {len(args.boxes)} for {len(args.split)}")
    return args


def run(args: argparse.Namespace) -> None:
    boxes = args.boxes or [None] * len(args.split)
    per_split = {s: split_rows(args.data, s, b, args.obj_id) for s, b in zip(args.split, boxes, strict=True)}
    table = []
    for name, rows in [*per_split.items(), ("together", [r for v in per_split.values() for r in v])]:
        if not rows:
            table.append([name, "0", "-", "-", "-", "-"])
            continue
        shown, unseen, own = np.array(rows).mean(0)
        share = f"{100 * unseen / own:.0f} %" if np.isfinite(own) else "-"
        own_text = f"{own:.3f}" if np.isfinite(own) else "-"
        table.append([name, str(len(rows)), f"{100 * shown:.0f} %", f"{unseen:.3f}", own_text, share])
    header = ["split", "clean-sky images", "visible px shown", "unseen loss", "detector's loss", "explained"]
    print(format_table(header, table))


if __name__ == "__main__":
    run_script(run, parse_args())
