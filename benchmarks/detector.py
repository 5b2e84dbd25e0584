"""Detector benchmark: train a preset, score its boxes per factor group, and pose with detected vs GT boxes.

    python benchmarks/detector.py --data DIR --out RUN [--config cpu] [--minutes 40] [--groups-n 50]
                                  [--pose-ckpt POSE/last.pt]

Trains `posenet train-detector`'s loop into RUN (resumes when RUN/last.pt exists; with --minutes, a new run
fitted to that wall time, and a run already in RUN is scored as it is), then scores RUN/best.pt (RUN/last.pt
without a val split) against the box it learns and the pose network is cropped around (`bbox_obj` clipped to
the image), with `bbox_visib`'s mean IoU beside it, on the whole test split and on each factor group of
`scgen.dataset.stats.sample_groups` (occlusion, distance, background), times the detector at batch 1 (median
per-image forward over the test split, current device), checks the floors (FLOOR_*) and writes the test
split's box file RUN/boxes_test.json, as `posenet boxes --detector` does. With --pose-ckpt, the pose
checkpoint is evaluated on the test split twice in this run, on ground-truth boxes and on that box file, side
by side: ADD@0.02 m, ADD@0.1d and the median rotation and translation errors, overall and per factor group (a
missed image fails every recall).
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path

import torch
from harness import parser, run_script

from posenet import evaluate
from posenet.detection.detect import box_scores, detect_split, detection_entries
from posenet.detection.detector import load_detector_config
from posenet.detection.train import BEST, train_detector
from posenet.evaluation.evaluate import EvalResult, format_table, summary_rows
from posenet.training.train import LAST
from scgen.dataset.stats import sample_groups
from scgen.io.atomic import atomic_write_text

# issue 50's floors for the CPU preset on the test split, its training <= 60 min on 2 cores, held since
# issue 62 on the box the detector learns (bbox_obj clipped to the image), where they were set on
# bbox_visib; a detector scores higher on its own box (12 min on the control set: 0.71-0.72 against
# 0.67-0.71 on held-out images, docs/benchmarks.md), so the same values ask no less of it
FLOOR_MEAN_IOU = 0.85  # a miss counting 0
FLOOR_IOU50 = 0.98  # share of images at IoU >= 0.5
FLOOR_MISSES = 0.01  # share of images without a detection


def parse_args() -> argparse.Namespace:
    p = parser(__doc__)
    p.add_argument("--data", type=Path, required=True, help="Rendered dataset (train, val, test splits).")
    p.add_argument("--out", type=Path, required=True, help="Detector run folder.")
    p.add_argument("--config", default="cpu", help="cpu | paper | a YAML/TOML file  [default: cpu]")
    p.add_argument("--max-steps", type=int, default=None, help="Stop training after N steps.")
    p.add_argument("--minutes", type=float, default=None, help="Wall-time budget of a new run (minutes).")
    p.add_argument("--groups-n", type=int, default=50, help="Samples per factor group.")
    p.add_argument("--groups-seed", type=int, default=0)
    p.add_argument("--pose-ckpt", type=Path, default=None, help="Pose checkpoint to evaluate on both boxes.")
    return p.parse_args()


def group_rows(groups: dict[str, dict[str, list[int]]]) -> list[tuple[str, set[int] | None]]:
    """('all', None), then ('factor/group', its sample ids) for every group (scgen: im_id = sample_id)."""
    return [("all", None)] + [(f"{f}/{g}", set(ids)) for f, gs in groups.items() for g, ids in gs.items()]


def pose_side_by_side(gt: EvalResult, det: EvalResult, groups: dict[str, dict[str, list[int]]]) -> str:
    """Per group, on GT and on detected boxes: the headline ADD@0.02 m and @0.1d (a missed image fails
    both) and the median rotation and translation errors (over the images with an estimate), and the
    misses."""
    rows = []
    every = {r["im_id"] for r in gt.records}
    for label, members in group_rows(groups):
        ids = every if members is None else every & members
        if not ids:
            continue
        on_gt, on_det = gt.summary_of(ids), det.summary_of(ids)
        cells = [
            f"{value:.3g}" if key.endswith("median") else f"{100 * value:.1f}"
            for key in ("add_0.02m", "add_0.1d", "re_deg_median", "te_m_median")
            for value in (on_gt[key], on_det[key])
        ]
        missed = sum(r.get("missed", False) for r in det.records if r["im_id"] in ids)
        rows.append([label, str(len(ids)), *cells, str(missed)])
    name = gt.summary["add_metric"]
    header = ["test group", "n", f"{name}@2cm GT", "det", f"{name}@0.1d GT", "det", "re med GT (deg)", "det",
              "te med GT (m)", "det", "missed"]  # fmt: skip
    return format_table(header, rows)


def floor_line(m: dict[str, float]) -> str:
    """Issue 50's box floors on the whole test split: mean IoU, share at IoU >= 0.5, misses."""
    checks = [
        (f"mean IoU {m['mean_iou']:.3f} >= {FLOOR_MEAN_IOU}", m["mean_iou"] >= FLOOR_MEAN_IOU),
        (f"IoU>=0.5 {100 * m['iou50']:.1f} % >= {100 * FLOOR_IOU50:.0f} %", m["iou50"] >= FLOOR_IOU50),
        (f"misses {100 * m['misses'] / m['n']:.1f} % <= {100 * FLOOR_MISSES:.0f} %",
         m["misses"] <= FLOOR_MISSES * m["n"]),
    ]  # fmt: skip
    return "floors: " + "; ".join(f"{text} {'met' if ok else 'NOT met'}" for text, ok in checks)


def run(args: argparse.Namespace) -> None:
    cfg = load_detector_config(args.config)
    if not (args.out / LAST).is_file() or args.minutes is None:
        resume = (args.out / LAST).is_file()
        train_detector(
            args.data, args.out, cfg, resume=resume, max_steps=args.max_steps, minutes=args.minutes
        )
    ckpt = args.out / BEST if (args.out / BEST).is_file() else args.out / LAST
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    images, dets, state = detect_split(ckpt, args.data, "test", cfg.obj_id, device)
    instances = {d.key: i for d, i in zip(dets, images, strict=True)}
    groups = sample_groups(args.data, "test", args.groups_n, args.groups_seed)["groups"]
    rows = []
    for name, members in group_rows(groups):
        sel = [d for d in dets if members is None or d.key[1] in members]
        m = box_scores(sel, [instances[d.key] for d in sel])
        rows.append([name, str(m["n"]), f"{100 * m['ap50']:.1f}", f"{m['mean_iou']:.3f}",
                     f"{m['visib_mean_iou']:.3f}", f"{100 * m['iou50']:.1f}", str(m["misses"])])  # fmt: skip
        if members is None:
            overall = m
    print(f"checkpoint: {ckpt} (step {state['step']})")
    columns = ["test group", "n", "AP50 (%)", "mean IoU", "mean IoU (bbox_visib)", "IoU>=0.5 (%)", "misses"]
    print(format_table(columns, rows))
    print(floor_line(overall))
    print(f"latency, batch 1 ({device.type}): {1000 * statistics.median(d.time_s for d in dets):.2f} ms")
    boxes = args.out / "boxes_test.json"
    atomic_write_text(boxes, json.dumps(detection_entries(dets, cfg.obj_id, f"detector:{ckpt}")) + "\n")
    print(f"wrote {boxes}")
    if args.pose_ckpt is not None:
        on_gt = evaluate(args.data, args.pose_ckpt, "test", workers=0)
        on_det = evaluate(args.data, args.pose_ckpt, "test", boxes=boxes, workers=0)
        print(f"\npose: {args.pose_ckpt}, test split, ground-truth boxes vs {boxes}")
        figures = ("missed", "re_deg", "re_deg_median", "te_m", "te_m_median", "add_0.02m", "add_0.1d", "esa")
        print(
            format_table(
                ["metric", "GT boxes", "detected boxes"],
                summary_rows([on_gt.summary, on_det.summary], figures),
            )
        )
        print(pose_side_by_side(on_gt, on_det, groups))


if __name__ == "__main__":
    run_script(run, parse_args())
