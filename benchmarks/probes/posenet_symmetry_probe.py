"""Why the from-scratch network's xyz head stays at the best constant: a probe of the target's near-symmetry.

The bundled spacecraft is close to symmetric under the three 180° turns about its axes (the group D2:
each turn flips the sign of two of x, y, z). Its bus is centred at the origin, so if the network can only
tell parts apart (wing, bus face, dish) but not which of the D2-related poses it sees, each signed
coordinate it must predict is +v or -v with equal odds, and the L1 loss's best answer is 0, the centroid:
exactly the constant prediction the coord loss sits at. Three arms train the CPU preset (augmentations on,
the real train_step) on the first `--subset` training images and print the xyz loss against the loss of
the batch's best constant (per-channel median), so a ratio of 1.0 means nothing learned:

- signed: the real targets;
- folded: targets |x|, |y|, |z| (invariant under D2): what part identity alone can predict;
- tinted: real targets, but the input image's visible pixels are tinted by the sign of their x, y, z,
  a local cue that breaks the symmetry pixel by pixel (not a rendering: a diagnostic input).

    python benchmarks/probes/posenet_symmetry_probe.py --data DS [--subset 64 --steps 400]

If folded and tinted learn while signed does not, the plateau is the symmetry, not the gradient path.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch.utils.data import DataLoader

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import parser, run_script

from posenet.config import load_config
from posenet.data import EpochSampler, open_split
from posenet.models import create_model
from posenet.training.train import (
    make_optimizer,
    pin_cpu_threads,
    pm_loss_points,
    steps_per_epoch,
    train_step,
    worker_init,
)

Batch = dict[str, torch.Tensor]


def folded(batch: Batch) -> Batch:
    """xyz targets (xyz / extent + 0.5) folded to 2·|xyz / extent|: the same for all D2-related poses."""
    return {**batch, "roi_xyz": (batch["roi_xyz"] - 0.5).abs() * 2 * batch["roi_mask_visib"]}


def tinted(batch: Batch) -> Batch:
    """Visible input pixels half replaced by the sign of their x, y, z as R, G, B."""
    scale = batch["roi_img"].shape[-1] // batch["roi_xyz"].shape[-1]
    visible = batch["roi_mask_visib"]
    sign = F.interpolate((batch["roi_xyz"] > 0.5).float() * visible, scale_factor=scale, mode="nearest")
    cover = F.interpolate(visible, scale_factor=scale, mode="nearest")
    return {**batch, "roi_img": batch["roi_img"] * (1 - 0.5 * cover) + 0.5 * sign}


ARMS: dict[str, Callable[[Batch], Batch]] = {"signed": lambda b: b, "folded": folded, "tinted": tinted}


def constant_loss(batch: Batch) -> float:
    """The coord loss of the batch's best constant prediction (per-channel median over visible pixels)."""
    xyz, visible = batch["roi_xyz"], batch["roi_mask_visib"][:, 0] > 0
    loss = sum((xyz[:, c][visible] - xyz[:, c][visible].median()).abs().sum() for c in range(3))
    return float(loss / visible.sum().clamp(min=1))


def run_arm(
    data: Path, arm: str, subset: int, steps: int, report_every: int
) -> list[tuple[int, float, float]]:
    """Train one arm from the same init; (step, mean coord loss, mean constant loss) per report window."""
    cfg = load_config("smoke")
    model_cfg = cfg.model_config()
    dataset = open_split(data, "train", cfg.data, model_cfg, train=True, seed=cfg.optim.seed)
    dataset.instances = dataset.instances[:subset]
    sampler = EpochSampler(len(dataset), cfg.optim.batch_size, seed=cfg.optim.seed)
    total = cfg.optim.epochs * steps_per_epoch(len(dataset), cfg.optim)
    torch.manual_seed(cfg.optim.seed)
    model = create_model(cfg.variant, cfg.preset, **cfg.model)
    optimizer, scheduler = make_optimizer(model, cfg.optim, total)
    points = pm_loss_points(dataset.obj, torch.device("cpu"))
    loader = DataLoader(
        dataset,
        batch_size=cfg.optim.batch_size,
        sampler=sampler,
        num_workers=cfg.data.workers,
        worker_init_fn=worker_init,
    )
    coord, const, rows = [], [], []
    for step, batch in enumerate(loader, start=1):  # the sampler's stream runs over the epochs' ends
        batch = ARMS[arm](batch)
        const.append(constant_loss(batch))
        coord.append(float(train_step(model, optimizer, batch, points, cfg)[1]))
        scheduler.step()
        if step % report_every == 0:
            rows.append((step, float(np.mean(coord[-report_every:])), float(np.mean(const[-report_every:]))))
        if step == steps:
            break
    return rows


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--data", type=Path, required=True, help="an scgen dataset (its train split is used)")
    ap.add_argument("--subset", type=int, default=64, help="first N training instances")
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--arms", default=",".join(ARMS), help="comma-separated subset of " + ", ".join(ARMS))
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    pin_cpu_threads(0)
    every = max(1, args.steps // 8)
    results = {}
    for arm in args.arms.split(","):
        start = time.perf_counter()
        results[arm] = run_arm(args.data, arm, args.subset, args.steps, every)
        print(f"{arm}: {time.perf_counter() - start:.0f} s", flush=True)
    print(f"\ncoord loss / best constant's, mean over {every} steps (1.00 = nothing learned)")
    print("step  " + "  ".join(f"{arm:>16}" for arm in results))
    for i, (step, *_) in enumerate(next(iter(results.values()))):
        cells = [f"{c:.3f}/{k:.3f} {c / k:.2f}" for c, k in (rows[i][1:] for rows in results.values())]
        print(f"{step:>4}  " + "  ".join(f"{cell:>16}" for cell in cells))


if __name__ == "__main__":
    run_script(run, parse_args())
