"""Issue 62's box-noise sweep with paired standard errors: ADD@0.1d per re-crop pass at the true boxes and
at perturbed ones, each set against the true boxes' first pass over the same images.

    python benchmarks/recrop_sweep.py --pose RUN/last.pt --data HELD_OUT --out /tmp/sweep \
        [--split train --split val --split test] [--noise 0.05 --noise 0.1 --noise 0.2] [--passes 3] \
        [--detector DET/best.pt ...]

For each box source (the ground truth, `posenet boxes --noise N` of each --noise, then `posenet boxes
--detector DET` of each --detector) and each pass
count up to --passes, `posenet.evaluate` scores every instance of the splits; an instance passes when its
ADD (ADD-S for a symmetric object, as posenet eval's add_0.1d) is under a tenth of the object's
diameter. A row's difference to the true boxes' first pass is the mean of the per-image differences
(+1, 0, -1), and its standard error their standard deviation over sqrt(n): paired, so what the images
share cancels. On a network whose ADD@0.1d flips on a fifth of the images from one pass to the next, a
single figure's binomial error overstates what two rows differ by, and the paired error is what a goal
of "within 1 point" is read against.

Writes OUT/results.json after every row (a re-run with the same --out resumes) and prints the table: per
row the mean IoU of each pass's crop box with bbox_obj, ADD@0.1d, the paired difference and its error,
and the images right only in that row / only at the true boxes.

Then the gate on the second pass (posenet predict's --same-crop-iou, posenet.predict.recrop.next_crop):
for each box source and each --gate G, the second pass runs only on the images whose model box at the
first pass's pose overlaps the first crop box by IoU < G, the others keeping their first pose. Its
ADD@0.1d follows from the two ungated passes image by image (every pass here runs ungated, --same-crop-iou
1); printed with the share of images it skips and its paired difference to two passes and to one.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import re
import statistics
import subprocess
import sys
from pathlib import Path

import numpy as np
from harness import parser, run_script

from posenet import Predictor, evaluate, make_camera
from posenet.data.boxes import MISS_PLACEHOLDER, read_boxes
from posenet.data.layout import scan_split
from posenet.errors import PosenetError
from posenet.evaluation.metrics import headline_add
from posenet.predict.recrop import box_iou, model_box

POSENET = Path(sys.executable).with_name("posenet")
GATES = (0.5, 0.6, 0.7, 0.75, 0.8, 0.85, 0.9, 0.95)


def parse() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--pose", type=Path, required=True, help="Pose checkpoint (posenet train's last.pt).")
    ap.add_argument("--data", type=Path, required=True, help="Held-out dataset (a scgen render).")
    ap.add_argument("--split", action="append", help="Splits scored together [train, val, test].")
    ap.add_argument("--noise", type=float, action="append", help="Box noise levels [0.05, 0.1, 0.2].")
    ap.add_argument("--passes", type=int, default=3, help="Most re-crop passes [3].")
    ap.add_argument("--detector", type=Path, action="append", default=[], help="Detector checkpoint: a row.")
    ap.add_argument("--out", type=Path, required=True, help="Working folder: boxes, results.json.")
    ap.add_argument("--gate", type=float, action="append", help=f"Second-pass gates, IoU {list(GATES)}.")
    return ap.parse_args()


@dataclasses.dataclass(frozen=True)
class BoxSource:
    """A table row's boxes: `key` names it in results.json, `option` is `posenet boxes`' (none: the
    ground truth, which eval reads itself)."""

    name: str
    key: str
    option: tuple[str, ...] = ()


def box_sources(args: argparse.Namespace) -> list[BoxSource]:
    """The ground truth, each --noise level, each --detector (keys of earlier runs kept: a re-run resumes)."""
    noisy = [BoxSource(f"noise {n:g}", f"{n:g}", ("--noise", str(n))) for n in args.noise or [0.05, 0.1, 0.2]]
    detected = [BoxSource(f"detector {d}", f"detector:{d}", ("--detector", str(d))) for d in args.detector]
    return [BoxSource("ground truth", "0"), *noisy, *detected]


def boxes_file(data: Path, split: str, source: BoxSource, out: Path) -> Path:
    """`posenet boxes` of `source` for one split, written once."""
    slug = re.sub(r"[^\w.-]+", "_", source.key)
    path = out / f"boxes_{slug}_{split}.json"
    if not path.exists():
        out.mkdir(parents=True, exist_ok=True)
        cmd = [str(POSENET), "boxes", "--data", str(data), "--split", split, "--out", str(path)]
        done = subprocess.run([*cmd, *source.option], capture_output=True, text=True)
        if done.returncode:  # posenet's own one-line error, passed on
            raise PosenetError(done.stderr.strip().splitlines()[-1].removeprefix("Error: "))
    return path


def score(args: argparse.Namespace, splits: list[str], source: BoxSource, passes: int) -> dict:
    """Per-image ADD@0.1d outcomes and the instance-weighted mean crop IoU of each pass; at one pass also
    each image's IoU of its model box at the pose with its crop box (`next_iou`: what the gate reads;
    none where the image has no pose or no model box)."""
    outcomes, next_iou, iou_sums, n = {}, {}, [0.0] * passes, 0
    obj = Predictor.load(args.pose).obj
    for split in splits:
        boxes = boxes_file(args.data, split, source, args.out) if source.option else None
        result = evaluate(
            args.data, args.pose, split, boxes=boxes, workers=2, passes=passes, same_crop_iou=1.0
        )
        add_key = headline_add(result.summary["symmetric"])[0]  # as posenet eval's add_0.1d: inf on a miss
        instances = {(i.scene_id, i.im_id): i for i in scan_split(args.data, split, obj.obj_id)}
        crops = read_boxes(boxes, obj.obj_id) if boxes else {k: i.bbox_obj for k, i in instances.items()}
        for record in result.records:
            key = f"{split}/{record['scene_id']}/{record['im_id']}"
            outcomes[key] = record[add_key] < 0.1 * result.diameter
            inst = instances[record["scene_id"], record["im_id"]]
            crop, again = crops.get((inst.scene_id, inst.im_id)), None
            if passes == 1 and record["R"] is not None and crop not in (None, MISS_PLACEHOLDER):
                camera = make_camera(inst.K, inst.dist, inst.image_size)
                R, t = np.reshape(record["R"], (3, 3)), np.asarray(record["t"], np.float64)
                again = model_box(obj, R, t, camera)
            next_iou[key] = box_iou(again, crop) if again is not None else None
        k = len(result.records)
        for i, iou in enumerate(result.summary.get("box_iou") or [1.0] * passes):
            iou_sums[i] += k * iou
        n += k
    return {"outcomes": outcomes, "box_iou": [s / n for s in iou_sums], "next_iou": next_iou}


def gated(first: dict, second: dict, gate: float) -> dict[str, bool]:
    """The outcomes with the second pass run only where the first pass's model box overlaps its crop box
    by IoU < `gate` (an image with no model box stops after one pass, as predict's does)."""
    iou = first["next_iou"]
    return {k: second["outcomes"][k] if iou[k] is not None and iou[k] < gate else v
            for k, v in first["outcomes"].items()}  # fmt: skip


def gate_table(results: dict, sources: list[BoxSource], gates: list[float]) -> str:
    """Per box source and gate: the images the second pass skips, ADD@0.1d, and its paired differences
    to two ungated passes and to one."""
    rows = ["| boxes | gate (IoU) | second pass skipped | ADD@0.1d | vs 2 passes | vs 1 pass |",
            "|---|---|---|---|---|---|"]  # fmt: skip
    for source in sources:
        first, second = results.get(f"{source.key}/1"), results.get(f"{source.key}/2")
        if first is None or second is None or "next_iou" not in first:
            continue
        for gate in gates:
            row = gated(first, second, gate)
            ious = first["next_iou"].values()
            skipped = sum(v is None or v >= gate for v in ious) / len(first["next_iou"])
            add = sum(row.values()) / len(row)
            (d2, se2, *_), (d1, se1, *_) = (paired_difference(row, r["outcomes"]) for r in (second, first))
            figures = f"{100 * skipped:.1f} % | {100 * add:.1f} % | {100 * d2:+.1f} ± {100 * se2:.1f} | "
            rows.append(f"| {source.name} | {gate:g} | {figures}{100 * d1:+.1f} ± {100 * se1:.1f} |")
    return "\n".join(rows)


def paired_difference(row: dict[str, bool], base: dict[str, bool]) -> tuple[float, float, int, int]:
    """(mean difference, its standard error, images right only in `row`, only in `base`)."""
    diffs = [int(row[k]) - int(base[k]) for k in base]
    se = statistics.stdev(diffs) / math.sqrt(len(diffs)) if len(diffs) > 1 else 0.0
    return statistics.fmean(diffs), se, diffs.count(1), diffs.count(-1)


def run(args: argparse.Namespace) -> None:
    splits = args.split or ["train", "val", "test"]
    sources = box_sources(args)
    path = args.out / "results.json"
    results = json.loads(path.read_text()) if path.exists() else {}
    for source in sources:
        for passes in range(1, args.passes + 1):
            key = f"{source.key}/{passes}"
            if key not in results or (passes == 1 and "next_iou" not in results[key]):
                results[key] = score(args, splits, source, passes)
                args.out.mkdir(parents=True, exist_ok=True)  # made once a row is scored: no empty OUT
                path.write_text(json.dumps(results))
    base = results["0/1"]["outcomes"]
    print(f"{len(base)} instances of {', '.join(splits)} in {args.data}; the base is the true boxes' pass 1")
    print("| boxes | passes | crop IoU per pass | ADD@0.1d | vs true, pass 1 | only here / only there |")
    print("|---|---|---|---|---|---|")
    for source in sources:
        for passes in range(1, args.passes + 1):
            row = results[f"{source.key}/{passes}"]
            mean, se, gained, lost = paired_difference(row["outcomes"], base)
            add = sum(row["outcomes"].values()) / len(row["outcomes"])
            ious = " / ".join(f"{v:.2f}" for v in row["box_iou"])
            print(f"| {source.name} | {passes} | {ious} | {100 * add:.1f} % "
                  f"| {100 * mean:+.1f} ± {100 * se:.1f} | {gained} / {lost} |")  # fmt: skip
    print()
    print(gate_table(results, sources, args.gate or list(GATES)))


if __name__ == "__main__":
    run_script(run, parse())
