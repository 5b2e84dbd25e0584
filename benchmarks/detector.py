"""Detector benchmark: train a preset on a dataset, then AP50, mean IoU and misses per factor group on test.

    python benchmarks/detector.py --data DIR --out RUN [--config cpu] [--max-steps N] [--groups-n 50]

Trains `posenet train-detector`'s loop into RUN (resumes when RUN/last.pt exists), then scores
RUN/best.pt (RUN/last.pt without a val split) against `bbox_visib` on the whole test split and on each
factor group of `scgen.stats.sample_groups` (occlusion, distance, background), and times the detector at
batch 1 (median per-image forward over the test split, current device).
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import torch

from posenet.detect import box_metrics, detect, detector_dataset, load_detector
from posenet.detector import image_groups, load_detector_config, visible_boxes
from posenet.evaluate import format_table
from posenet.train import LAST
from posenet.train_detector import BEST, train_detector
from scgen.stats import sample_groups


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, required=True, help="Rendered dataset (train, val, test splits).")
    p.add_argument("--out", type=Path, required=True, help="Detector run folder.")
    p.add_argument("--config", default="cpu", help="cpu | paper | a YAML/TOML file  [default: cpu]")
    p.add_argument("--max-steps", type=int, default=None, help="Stop training after N steps.")
    p.add_argument("--groups-n", type=int, default=50, help="Samples per factor group.")
    p.add_argument("--groups-seed", type=int, default=0)
    return p.parse_args()


def main() -> None:
    args = parse_args()
    cfg = load_detector_config(args.config)
    resume = (args.out / LAST).is_file()
    train_detector(args.data, args.out, cfg, resume=resume, max_steps=args.max_steps)
    ckpt = args.out / BEST if (args.out / BEST).is_file() else args.out / LAST
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    model, state = load_detector(ckpt, device)
    images = image_groups(args.data, "test", cfg.obj_id)
    dets = detect(model, detector_dataset(state, images), device)
    gt = {d.key: visible_boxes(i) for d, i in zip(dets, images, strict=True)}
    groups = sample_groups(args.data, "test", args.groups_n, args.groups_seed)["groups"]
    rows = []
    for name, members in [("all", None)] + [
        (f"{f}/{g}", set(ids)) for f, gs in groups.items() for g, ids in gs.items()
    ]:
        sel = [d for d in dets if members is None or d.key[1] in members]  # scgen: im_id = sample_id
        m = box_metrics(sel, [gt[d.key] for d in sel])
        rows.append([name, str(m["n"]), f"{100 * m['ap50']:.1f}", f"{m['mean_iou']:.3f}", str(m["misses"])])
    print(f"checkpoint: {ckpt} (step {state['step']})")
    print(format_table(["test group", "n", "AP50 (%)", "mean IoU", "misses"], rows))
    print(f"latency, batch 1 ({device.type}): {1000 * statistics.median(d.time_s for d in dets):.2f} ms")


if __name__ == "__main__":
    main()
