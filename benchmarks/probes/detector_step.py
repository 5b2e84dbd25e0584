"""Detector training step time, in training's memory format and in the default one, side by side.

Times `posenet.detection.train.detector_step` (FCOS forward with its losses, backward, Ranger step) of
--config on one fixed batch of the dataset's training images, augmented as training augments them, on
the current device. The weights are laid out as training lays them out (posenet.training.train.memory_format:
channels-last on a CPU) and, on a CPU, also in the default contiguous format.

Usage: python benchmarks/probes/detector_step.py --data DIR [--config cpu] [--steps 20]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import parser, run_script

from posenet.detection.detector import (
    DetectionDataset,
    DetectorConfig,
    build_detector,
    collate,
    image_groups,
    load_detector_config,
)
from posenet.detection.train import detector_step
from posenet.training.train import compared_layouts, make_optimizer, pin_cpu_threads

WARMUP = 3  # untimed steps (allocator, oneDNN kernel selection)


def step_time(
    data: Path, cfg: DetectorConfig, steps: int, layout: torch.memory_format, device: torch.device
) -> float:
    """Seconds per training step of `cfg`'s detector on `device`, with weights in `layout`."""
    dataset = DetectionDataset(image_groups(data, "train", cfg.obj_id), cfg, train=True, seed=cfg.optim.seed)
    images, targets = collate([dataset[i] for i in range(cfg.optim.batch_size)])
    torch.manual_seed(cfg.optim.seed)
    model = build_detector(cfg.model_dict(), cfg.pretrained).to(device, memory_format=layout).train()
    optimizer, _ = make_optimizer(model, cfg.optim, total_iters=steps + WARMUP)
    times = []
    for _ in range(steps + WARMUP):
        tic = time.perf_counter()
        detector_step(model, optimizer, images, targets, device)
        if device.type == "cuda":
            torch.cuda.synchronize()
        times.append(time.perf_counter() - tic)
    return sum(times[WARMUP:]) / steps


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--data", type=Path, required=True, help="An scgen dataset with a train split.")
    ap.add_argument("--config", default="cpu", help="cpu | paper | a detector config file [cpu].")
    ap.add_argument("--steps", type=int, default=20, help="Timed steps per layout.")
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    cfg = load_detector_config(args.config)
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if device.type == "cpu":
        pin_cpu_threads(cfg.optim.threads)
    bs = cfg.optim.batch_size
    for layout, what in compared_layouts(device):
        sec = step_time(args.data, cfg, args.steps, layout, device)
        print(f"detector train step ({args.config}, batch {bs}, {device.type}, {what}): {1e3 * sec:.0f} ms")


if __name__ == "__main__":
    run_script(run, parse_args())
