"""The multi-class detector's boxes per object class on a dataset of several labelled objects.

    python benchmarks/detector_classes.py --data DIR --out RUN [--config cpu] [--minutes 20]

Trains `posenet train-detector`'s loop on every object of DIR (one class per obj_id of models_info.json)
into RUN, resuming RUN/last.pt where it exists (with --minutes, a new run fitted to that wall time; a run
already in RUN is scored as it is), then scores RUN/best.pt (RUN/last.pt without a val split) on the test
split, class by class: every ground-truth instance with a visible pixel (its box the one the detector
learns, bbox_obj clipped to the image) is matched to a box of its class scoring at least `posenet
predict`'s floor (posenet.detection.options.MIN_SCORE), greedily by IoU (each box matched once; an
unmatched instance counts IoU 0). Printed per class and over all instances: instances, mean IoU, the
share at IoU >= 0.5, and the class's boxes over the floor matched to no instance (false positives).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
from harness import parser, run_script

from posenet.detection.detect import detect, detector_dataset, detector_obj_ids, iou, load_detector
from posenet.detection.detector import image_groups, load_detector_config, target_boxes
from posenet.detection.options import MIN_SCORE
from posenet.detection.train import BEST, train_detector
from posenet.evaluation.evaluate import format_table
from posenet.training.train import LAST
from scgen.dataset.layout import object_names, open_dataset


def match_class(found: list[tuple[float, ...]], truth: np.ndarray) -> tuple[list[float], int]:
    """(IoU of each ground-truth box with the kept box it is matched to, 0 where none; the kept boxes
    left unmatched): greedy, the pairs of highest IoU first, each box and instance matched once."""
    pairs = [(iou(f, truth[g : g + 1]), fi, g) for fi, f in enumerate(found) for g in range(len(truth))]
    ious, used = [0.0] * len(truth), set()
    for value, fi, g in sorted(pairs, reverse=True):
        if value > 0 and fi not in used and ious[g] == 0.0:
            ious[g] = value
            used.add(fi)
    return ious, len(found) - len(used)


def table_row(label: str, ious: list[float], unmatched: int) -> list[str]:
    if not ious:
        return [label, "0", "-", "-", str(unmatched)]
    recall = 100 * np.mean([v >= 0.5 for v in ious])
    return [label, str(len(ious)), f"{np.mean(ious):.3f}", f"{recall:.1f}", str(unmatched)]


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--config", default="cpu", help="detector preset or YAML [cpu]")
    ap.add_argument("--minutes", type=float, default=None, help="fit a new run to this wall time")
    ap.add_argument("--max-steps", type=int, default=None)
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    names = object_names(open_dataset(args.data)[1])
    cfg = load_detector_config(args.config, dataset_ids=sorted(names))
    if not (args.out / LAST).is_file() or args.minutes is None:
        resume = (args.out / LAST).is_file()
        train_detector(args.data, args.out, cfg, resume, args.max_steps, args.minutes)
    ckpt = args.out / BEST if (args.out / BEST).is_file() else args.out / LAST
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    model, state = load_detector(ckpt, device)
    classes = detector_obj_ids(state)
    images = image_groups(args.data, "test", classes)
    dets = detect(model, detector_dataset(state, images), device)
    ious: dict[int, list[float]] = {k: [] for k in classes}
    unmatched = dict.fromkeys(classes, 0)
    for det, instances in zip(dets, images, strict=True):
        for k in classes:
            found = [f.box for f in det.found if f.obj_id == k and f.score >= MIN_SCORE]
            got, extra = match_class(found, target_boxes([i for i in instances if i.obj_id == k]))
            ious[k] += got
            unmatched[k] += extra
    rows = [table_row(f"{k} {names.get(k, '')}", ious[k], unmatched[k]) for k in classes]
    rows.append(table_row("all", [v for k in classes for v in ious[k]], sum(unmatched.values())))
    print(
        f"checkpoint: {ckpt} (step {state['step']}), test split, {len(images)} images, score >= {MIN_SCORE}"
    )
    print(format_table(["class (obj_id)", "instances", "mean IoU", "IoU>=0.5 (%)", "unmatched boxes"], rows))


if __name__ == "__main__":
    run_script(run, parse_args())
