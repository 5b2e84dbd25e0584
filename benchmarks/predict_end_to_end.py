"""posenet predict end to end, as a user runs it: only images and one camera file, detector boxes, scored
against the labels they came with, beside posenet eval at ground-truth boxes on the same images.

    python benchmarks/predict_end_to_end.py --pose RUN/last.pt --detector DET/best.pt \\
        --data HELD_OUT_CORRIDOR --data HELD_OUT_DEFAULT --out /tmp/e2e [--split test] [--scale 2] \\
        [--passes 2] [--same-crop-iou G]

For each --data (a scgen render the checkpoints were not trained on), the images of its split that show
the object are copied, renamed, into OUT/NAME/input with the dataset's camera.json and nothing else; then
`posenet predict` runs on that folder with the detector, in torch and (after `posenet export` of both
networks) in onnxruntime. Each written prediction is scored against its label: rotation median, ADD@0.1d
(posenet.evaluation.metrics), and the detector's IoU against bbox_visib; beside it, `posenet eval` at the
ground-truth boxes. predict's own images per second (the batch, model loading excluded) are read from its
output. With --scale S the user's copies are the images resized S times (bicubic) with camera.json's
intrinsics scaled alike (posenet.data.camera.resized): a user camera of S times the size, which
predict warps back into the training camera; the labels and the poses do not change. --passes N runs
predict and eval at N passes alike (default: predict's, posenet.predict.options.PREDICT_PASSES; the
figures of issue 50 were at 1), and --same-crop-iou G gates the passes after the first alike (default:
predict's, SAME_CROP_IOU; 1 runs every pass).
--passes-table instead runs only onnxruntime's predict, at its defaults and at --passes 1 and --passes 2
--same-crop-iou 1 (every second pass), in turn for --rounds rounds, and prints each setting's median
images/s beside its ADD@0.1d (issue 80: the default's speed and accuracy against the two it sits
between); OUT/passes.json.
Writes OUT/report.json and prints one table. The goal of issue 50: ADD@0.1d at detected boxes within 3
points of that at ground-truth boxes, and >= 30 images/s at 640x480 through ONNX on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import statistics
import subprocess
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from harness import parser, run_script

from posenet import Predictor, evaluate
from posenet.checkpoint import load_checkpoint
from posenet.config import config_from_dict
from posenet.data.camera import read_camera_file, resized
from posenet.data.layout import Instance, scan_split
from posenet.detection.detect import iou
from posenet.errors import PosenetError
from posenet.evaluation.metrics import sample_errors, summarise
from posenet.predict.options import PREDICT_PASSES, SAME_CROP_IOU
from scgen.io import bop

POSENET = [sys.executable, "-m", "posenet.cli"]


def user_folder(data: Path, split: str, obj_id: int, folder: Path, scale: float) -> dict[str, Instance]:
    """The split's images showing the object, copied as a user would hold them (resized `scale` times),
    with camera.json; the instance behind each file name."""
    folder.mkdir(parents=True, exist_ok=True)
    camera = read_camera_file(data / bop.CAMERA_FILE)
    assert camera.size is not None
    size = (round(camera.size[0] * scale), round(camera.size[1] * scale))
    K = resized(camera, size).K
    spec = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2], "width": size[0], "height": size[1]}
    (folder / "camera.json").write_text(json.dumps(spec, indent=1) + "\n")
    names = {}
    for inst in scan_split(data, split, obj_id):
        if inst.px_count_visib <= 0:
            continue
        name = f"img_{inst.scene_id:06d}_{inst.im_id:06d}{inst.rgb.suffix}"
        if scale == 1:
            shutil.copy(inst.rgb, folder / name)
        else:
            cv2.imwrite(
                str(folder / name), cv2.resize(cv2.imread(str(inst.rgb)), size, interpolation=cv2.INTER_CUBIC)
            )
        names[name] = inst
    return names


def run_predict(args: list[Any]) -> tuple[Path, float]:
    """`posenet predict ARGS`; its OUT and its printed images per second."""
    res = subprocess.run([*POSENET, "predict", *map(str, args)], capture_output=True, text=True)
    if res.returncode != 0:  # its error is its last line
        last = (res.stderr.strip().splitlines() or ["no message"])[-1]
        raise PosenetError(f"posenet predict exited with status {res.returncode}: {last}")
    rate = float(re.search(r"([\d.]+) images/s", res.stdout).group(1))  # type: ignore[union-attr]
    return Path(args[args.index("--out") + 1]), rate


def score(
    predictions: Path, names: dict[str, Instance], predictor: Predictor, scale: float
) -> dict[str, Any]:
    """Pose figures (posenet.evaluation.metrics.summarise) and box figures of a predictions.jsonl against
    its labels
    (boxes in the user's image, `scale` times the labelled one, are scaled back)."""
    obj = predictor.obj
    geometry = [torch.from_numpy(a) for a in (obj.pm_points, obj.vertices, obj.symmetries)]
    errors: dict[str, list[float]] = {}
    ious = []
    for line in predictions.read_text().splitlines():
        r = json.loads(line)
        inst = names[Path(r["source"]).name]
        x, y, w, h = inst.bbox_visib  # covers pixels x .. x + w - 1: edges x - 0.5 .. x + w - 0.5
        gt_box = np.array([[x - 0.5, y - 0.5, x + w - 0.5, y + h - 0.5]])
        if r["R"] is None:
            ious.append(0.0)
            e = {k: float("inf") for k in ("re_deg", "re_sym_deg", "te_m", "tz_rel", "add_m", "add_rot_m",
                                            "adds_m", "mssd_m", "esa")}  # fmt: skip
        else:
            bx, by, bw, bh = ((v + 0.5) / scale - 0.5 if i < 2 else v / scale for i, v in enumerate(r["box"]))
            ious.append(iou((bx - 0.5, by - 0.5, bx + bw - 0.5, by + bh - 0.5), gt_box))
            R, t = torch.tensor(r["R"]).reshape(1, 3, 3), torch.tensor(r["t"])[None]
            gt_R, gt_t = torch.from_numpy(inst.R)[None], torch.from_numpy(inst.t)[None]
            e = {k: float(v[0]) for k, v in sample_errors(R, t, gt_R, gt_t, *geometry).items()}
        for k, v in e.items():
            errors.setdefault(k, []).append(v)
    summary = summarise(errors, obj.diameter, obj.symmetric)
    summary |= {"mean_iou": float(np.mean(ious)), "iou50": float(np.mean(np.array(ious) >= 0.5)),
                "misses": len(errors["re_deg"]) - int(np.isfinite(errors["re_deg"]).sum())}  # fmt: skip
    return summary


def one_dataset(data: Path, out: Path, args: argparse.Namespace, onnx: tuple[Path, Path]) -> dict[str, Any]:
    obj_id = config_from_dict(load_checkpoint(args.pose)["config"]).data.obj_id
    names = user_folder(data, args.split, obj_id, out / "input", args.scale)
    predictor = Predictor.load(args.pose)
    common = [
        out / "input",
        "--ckpt",
        args.pose,
        "--camera",
        out / "input" / "camera.json",
        "--no-vis",
        "--overwrite",
        "--passes",
        args.passes,
        "--same-crop-iou",
        args.same_crop_iou,
    ]
    torch_out, torch_rate = run_predict([*common, "--detector", args.detector, "--out", out / "torch"])
    onnx_out, onnx_rate = run_predict(
        [*common, "--detector", onnx[1], "--onnx", onnx[0], "--out", out / "onnx"]
    )
    gt = evaluate(
        data, args.pose, args.split, workers=0, passes=args.passes, same_crop_iou=args.same_crop_iou
    ).summary
    return {
        "data": str(data),
        "images": len(names),
        "scale": args.scale,
        "detected": score(torch_out / "predictions.jsonl", names, predictor, args.scale),
        "detected_onnx": score(onnx_out / "predictions.jsonl", names, predictor, args.scale),
        "ground_truth_boxes": gt,
        "images_per_s": {"torch": torch_rate, "onnx": onnx_rate},
    }


PASSES_SETTINGS = {  # --passes-table's rows: predict's options for each
    "1 pass": ["--passes", "1"],
    "2 passes": ["--passes", "2", "--same-crop-iou", "1"],
    "default": [],
}


def passes_rows(data: Path, out: Path, args: argparse.Namespace, onnx: tuple[Path, Path]) -> dict[str, Any]:
    """onnxruntime's predict at each PASSES_SETTINGS, the settings in turn for args.rounds rounds: its
    images/s per round and the figures of its poses (the same every round: predict is deterministic)."""
    obj_id = config_from_dict(load_checkpoint(args.pose)["config"]).data.obj_id
    names = user_folder(data, args.split, obj_id, out / "input", args.scale)
    predictor = Predictor.load(args.pose)
    common = [out / "input", "--ckpt", args.pose, "--camera", out / "input" / "camera.json", "--no-vis",
              "--overwrite", "--detector", onnx[1], "--onnx", onnx[0]]  # fmt: skip
    rows: dict[str, Any] = {name: {"images_per_s": []} for name in PASSES_SETTINGS}
    for _ in range(args.rounds):
        for name, options in PASSES_SETTINGS.items():
            folder, rate = run_predict([*common, *options, "--out", out / name.replace(" ", "_")])
            rows[name]["images_per_s"].append(rate)
            rows[name]["poses"] = score(folder / "predictions.jsonl", names, predictor, args.scale)
    return {"data": str(data), "images": len(names), "scale": args.scale, "rows": rows}


def passes_table(report: dict[str, Any]) -> str:
    head = "| set | predict | images/s (median; each round) | ADD@0.1d | rotation median | misses |"
    lines = [head, "|---|---|---|---|---|---|"]
    for set_name, r in report.items():
        for name, row in r["rows"].items():
            rates, s = row["images_per_s"], row["poses"]
            speed = f"{statistics.median(rates):.1f} ({', '.join(f'{v:.1f}' for v in rates)})"
            pose = f"{100 * s['add_0.1d']:.1f} % | {s['re_deg_median']:.2f} deg | {s['misses']}"
            lines.append(f"| {set_name} | {name} | {speed} | {pose} |")
    return "\n".join(lines)


def table(report: dict[str, Any]) -> str:
    head = "| set | images | boxes | rotation median | ADD@0.1d | mean IoU | IoU >= 0.5 | misses | images/s |"
    rows = [head, "|---|---|---|---|---|---|---|---|---|"]
    for set_name, r in report.items():
        width = json.loads((Path(r["data"]) / bop.CAMERA_FILE).read_text())["width"]
        name = f"{set_name}, {round(width * r['scale'])} px wide"
        for label, key, rate in (
            ("detector, torch", "detected", "torch"),
            ("detector, ONNX", "detected_onnx", "onnx"),
        ):
            s, speed = r[key], r["images_per_s"][rate]
            pose = f"{s['re_deg_median']:.2f} deg | {100 * s['add_0.1d']:.1f} %"
            boxes = f"{s['mean_iou']:.3f} | {100 * s['iou50']:.1f} % | {s['misses']}"
            rows.append(f"| {name} | {r['images']} | {label} | {pose} | {boxes} | {speed:.1f} |")
        g = r["ground_truth_boxes"]
        rows.append(f"| {name} | {r['images']} | ground truth (eval) | {g['re_deg_median']:.2f} deg | "
                    f"{100 * g['add_0.1d']:.1f} % | | | | |")  # fmt: skip
    return "\n".join(rows)


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--pose", type=Path, required=True, help="Pose checkpoint (posenet train's last.pt).")
    ap.add_argument("--detector", type=Path, required=True, help="Detector checkpoint (train-detector's).")
    ap.add_argument(
        "--data", type=Path, action="append", required=True, help="Held-out dataset (repeatable)."
    )
    ap.add_argument("--split", default="test", help="Split of each --data [test].")
    ap.add_argument("--out", type=Path, required=True, help="Working and report folder.")
    ap.add_argument("--scale", type=float, default=1.0, help="Resize the user's images S times [1].")
    runs = f"Pose network runs per image, predict's and eval's [{PREDICT_PASSES}, posenet predict's]."
    ap.add_argument("--passes", type=int, default=PREDICT_PASSES, help=runs)
    gate = f"The passes' gate, predict's and eval's [{SAME_CROP_IOU}, posenet predict's]."
    ap.add_argument("--same-crop-iou", type=float, default=SAME_CROP_IOU, help=gate)
    ap.add_argument("--passes-table", action="store_true", help="onnxruntime at 1, 2 and the default passes.")
    ap.add_argument("--rounds", type=int, default=3, help="--passes-table's rounds of the settings [3].")
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    args.out.mkdir(parents=True, exist_ok=True)
    onnx = (args.out / "onnx" / "pose.onnx", args.out / "onnx" / "detector.onnx")
    if not all(p.is_file() for p in onnx):
        export = ["export", "--ckpt", args.pose, "--onnx", onnx[0], "--detector", args.detector]
        subprocess.run([*POSENET, *export, "--detector-onnx", onnx[1], "--overwrite"], check=True)
    if args.passes_table:
        report = {d.name: passes_rows(d, args.out / d.name, args, onnx) for d in args.data}
        (args.out / "passes.json").write_text(json.dumps(report, indent=2) + "\n")
        print(passes_table(report))
        return
    report = {d.name: one_dataset(d, args.out / d.name, args, onnx) for d in args.data}
    (args.out / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    print(table(report))


if __name__ == "__main__":
    run_script(run, parse_args())
