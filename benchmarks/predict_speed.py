"""predict's images per second by stage, one image at a time beside batched, in one run (issue 63 item 3).

    python benchmarks/predict_speed.py --pose POSE.pt --detector DET.pt --images DIR \\
        [--camera DIR/camera.json] [--device cpu|cuda] [--n 64] [--batch 16] [--threads T] \\
        [--onnx POSE.onnx --detector-onnx DET.onnx] [--preset paper [--variant gdrnet]] [--passes 2] \\
        [--json OUT.json]
    python benchmarks/predict_speed.py --pose POSE.pt --detector DET.pt --images DIR --make-kit KIT

The first --n images of DIR (sorted) go through predict with the detector, as `posenet predict` runs them,
in these modes, each after a warm-up on one batch (cuDNN's choices, a CUDA graph's capture):
  one            posenet.predict.Predictor, one image at a time (posenet predict without --batch);
  batch          posenet.predict.batch.BatchPredictor at --batch, images decoded and warped in threads;
  batch+graphs   (CUDA) the same at fixed shapes with both networks replayed as CUDA graphs;
  ...+bf16       (CUDA) and under bf16 autocast;
  onnx, onnx batch   (with --onnx) the pose network in onnxruntime, batched; a .onnx detector per image.
For each mode it prints images/s per stage (1000 / the stage's ms per image: decode, detector, crop (the
warp into the training camera included), pose network, solve) and end to end (images / wall seconds,
decoding included, no drawing or writing), and how far each batched mode's poses lie from the one-at-a-time
ones of the same runtime (largest |dR| entry, largest |dt| / |t|, flags that differ). --json is rewritten
after every mode.

--preset P [--variant V]: the pose network rebuilt at random init in preset P (paper: GDR-Net's ResNet-34
at 256 px), keeping the checkpoint's object and camera: speed does not depend on the weights, and a
paper-size checkpoint is larger than a GPU node's carry. --detector-config C: the detector rebuilt alike
(cpu: FCOS on an EfficientNet-Lite0 FPN, paper: on ResNet-50; a preset keeps the checkpoint's input size).
--make-kit KIT writes what a GPU node needs into KIT instead (the --n images, camera.json, both
checkpoints stripped to what predict reads); then, on the node:
    python benchmarks/predict_speed.py --kit KIT --device cuda --preset paper --detector-config cpu \\
        --batch 64 --json OUT.json
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from harness import parser, positive, run_script
from harness.predict import SHOWN, images_of, measure

from posenet.checkpoint import load_checkpoint, save_checkpoint
from posenet.data.camera import read_camera_file
from posenet.errors import PosenetError
from posenet.models import create_model
from posenet.predict.batch import BatchPredictor
from posenet.predict.options import PREDICT_PASSES
from posenet.predict.predictor import Predictor

KEEP = ("model", "model_config", "config", "step", "object", "camera")  # what predict and export read


def make_kit(args: argparse.Namespace) -> None:
    """KIT/images, KIT/camera.json, KIT/pose.pt and KIT/detector.pt: a GPU node's carry."""
    (args.make_kit / "images").mkdir(parents=True, exist_ok=True)
    for path in images_of(args.images, args.n):
        shutil.copy(path, args.make_kit / "images" / path.name)
    shutil.copy(args.camera or args.images / "camera.json", args.make_kit / "camera.json")
    for src, name in ((args.pose, "pose.pt"), (args.detector, "detector.pt")):
        state = load_checkpoint(src)
        save_checkpoint(args.make_kit / name, {k: state[k] for k in KEEP if k in state})
    size = sum(p.stat().st_size for p in args.make_kit.rglob("*") if p.is_file())
    print(f"wrote {args.make_kit}: {size / 2**20:.1f} MiB")


def rebuilt(ckpt: Path, preset: str, variant: str | None, folder: Path) -> Path:
    """The checkpoint with its network rebuilt at random init in `preset` (object and camera kept)."""
    state = load_checkpoint(ckpt, kind="pose")
    model = create_model(variant or state["model_config"]["variant"], preset)
    state = {k: state[k] for k in KEEP} | {
        "model": model.state_dict(),
        "model_config": model.config.to_dict(),
    }
    save_checkpoint(folder / "pose.pt", state)
    return folder / "pose.pt"


def rebuilt_detector(ckpt: Path, config: str, folder: Path) -> Path:
    """The detector checkpoint with its network rebuilt at random init from `config` (a preset or a file);
    a preset keeps the checkpoint's input size (min_size, max_size)."""
    from posenet.detection.detector import build_detector, load_detector_config

    state = load_checkpoint(ckpt, kind="detector")
    model_config = load_detector_config(config).model_dict()
    if not Path(config).is_file():
        model_config |= {k: state["model_config"][k] for k in ("min_size", "max_size")}
    model = build_detector(model_config, None)
    save_checkpoint(
        folder / "detector.pt", {**state, "model": model.state_dict(), "model_config": model_config}
    )
    return folder / "detector.pt"


def difference(ref: list[Any], poses: list[Any]) -> dict[str, Any]:
    """How far `poses` lie from the one-at-a-time `ref`."""
    both = [(a, b) for a, b in zip(ref, poses, strict=True) if a.R is not None and b.R is not None]
    dR = max((float(np.abs(a.R - b.R).max()) for a, b in both), default=0.0)
    dt = max((float(np.linalg.norm(a.t - b.t) / np.linalg.norm(a.t)) for a, b in both), default=0.0)
    flags = sum(a.flags != b.flags for a, b in zip(ref, poses, strict=True))
    return {"max_dR": dR, "max_dt_rel": dt, "flags_differ": flags}


def line(row: dict[str, Any]) -> str:
    rates = " ".join(f"{s} {row['images_per_s'].get(s, float('nan')):.0f}" for s in SHOWN)
    diff = row.get("vs_one")
    tail = ""
    if diff:
        tail = f"; vs one: |dR| {diff['max_dR']:.1e}, |dt|/|t| {diff['max_dt_rel']:.1e}, "
        tail += f"flags {diff['flags_differ']}"
    return f"{row['mode']:<22} {row['end_to_end']:8.1f} images/s end to end | {rates} (images/s){tail}"


def run(args: argparse.Namespace) -> None:
    if args.make_kit is not None:
        make_kit(args)
        return
    images, camera_path = args.images, args.camera
    pose, detector = args.pose, args.detector
    if args.kit is not None:
        images, pose, detector = args.kit / "images", args.kit / "pose.pt", args.kit / "detector.pt"
        camera_path = camera_path or args.kit / "camera.json"
    if images is None or pose is None or detector is None:
        raise PosenetError("give --kit KIT, or --pose, --detector and --images")
    if args.threads:
        torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    if device.type == "cuda":
        torch.backends.cudnn.benchmark = True  # fixed shapes: the fastest kernels, chosen once
    paths = images_of(images, args.n)
    camera = read_camera_file(camera_path or images / "camera.json")
    first = cv2.imread(str(paths[0]))
    report: dict[str, Any] = {"device": str(device), "n": len(paths), "batch": args.batch,
                              "image": list(first.shape[1::-1]), "rows": []}  # fmt: skip
    if device.type == "cuda":
        report["gpu"] = torch.cuda.get_device_name(device)
    with tempfile.TemporaryDirectory() as tmp:
        if args.preset:
            pose = rebuilt(pose, args.preset, args.variant, Path(tmp))
        if args.detector_config:
            detector = rebuilt_detector(detector, args.detector_config, Path(tmp))
        modes: list[tuple[str, Path | None, Path, dict[str, Any]]] = [
            ("one", None, detector, {}),
            ("batch", None, detector, {}),
        ]
        if device.type == "cuda":
            modes += [("batch+graphs", None, detector, {"graphs": True}),
                      ("batch+graphs+bf16", None, detector, {"graphs": True, "bf16": True})]  # fmt: skip
        if args.onnx is not None:
            det = args.detector_onnx or detector
            modes += [("onnx one", args.onnx, det, {}), ("onnx batch", args.onnx, det, {})]
        refs: dict[bool, list[Any]] = {}  # the one-at-a-time poses, torch's and onnxruntime's
        for name, onnx, det, options in modes:
            predictor = Predictor.load(pose, det, device, onnx=onnx, min_score=0.0, passes=args.passes)
            batched = None
            if "batch" in name:
                batched = BatchPredictor(predictor, args.batch, det, threads=args.threads or None, **options)
            try:
                row, poses = measure(predictor, paths, camera, batched)
                row = {"mode": name, **row}
                if batched is None:
                    refs[onnx is not None] = poses
                else:  # bf16 (8 bits) may move a pose by ~2^-8 of its scale
                    row["vs_one"] = difference(refs[onnx is not None], poses)
                print(line(row), flush=True)
            except Exception as exc:  # a mode that fails on a node (a capture, bf16): a line, not the end
                row = {"mode": name, "error": repr(exc)[:500]}
                print(f"{name:<22} failed: {exc!r}"[:300], flush=True)
            report["rows"].append(row)
            if args.json:
                args.json.write_text(json.dumps(report, indent=1) + "\n")
            if batched is not None:
                batched.close()


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--pose", type=Path, help="Pose checkpoint (posenet train's last.pt).")
    ap.add_argument("--detector", type=Path, help="Detector checkpoint (train-detector's).")
    ap.add_argument("--images", type=Path, help="Folder of images (and its camera.json).")
    ap.add_argument("--camera", type=Path, default=None, help="Their camera file [IMAGES/camera.json].")
    ap.add_argument(
        "--kit", type=Path, default=None, help="A --make-kit folder: images, camera, checkpoints."
    )
    ap.add_argument("--make-kit", type=Path, default=None, help="Write a GPU node's carry here and stop.")
    ap.add_argument("--device", default="cpu", help="cpu or cuda [cpu].")
    ap.add_argument("--n", type=positive, default=64, help="Images measured [64].")
    ap.add_argument("--batch", type=positive, default=16, help="The batched modes' batch size [16].")
    runs = f"Pose network runs per image (re-crops) [{PREDICT_PASSES}, posenet predict's]."
    ap.add_argument("--passes", type=positive, default=PREDICT_PASSES, help=runs)
    ap.add_argument("--threads", type=int, default=0, help="torch and pool threads [0: the defaults].")
    ap.add_argument("--onnx", type=Path, default=None, help="The pose network's ONNX graph: the onnx modes.")
    ap.add_argument("--detector-onnx", type=Path, default=None, help="The detector's, for the onnx modes.")
    ap.add_argument("--preset", default=None, help="Rebuild the pose network at random init in this preset.")
    ap.add_argument("--variant", default=None, help="... of this variant [the checkpoint's].")
    ap.add_argument("--detector-config", default=None, help="Rebuild the detector at random init so.")
    ap.add_argument("--json", type=Path, default=None, help="Write the figures here after every mode.")
    return ap.parse_args()


if __name__ == "__main__":
    run_script(run, parse_args())
