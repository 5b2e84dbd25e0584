"""posenet input pipeline and training step speed.

Prints (1) training samples/s of one loader process with the paper's augmentations (DZI, brightness/
contrast at p=0.8, background replacement at p=0.5) at the paper's 256/64 resolution, (2) the DataLoader
throughput with --workers processes, (3) the training step time (forward, losses, backward, Ranger step)
of --config (or each --variant) on the current device (paper on a GPU, smoke on a CPU by default), with
the weights and images in training's memory format (posenet.training.train.memory_format:
channels-last on a CPU) and, on a CPU, also in the default contiguous one, side by side.

Usage: python benchmarks/posenet_dataloader.py [--data DIR] [--workers 2] [--batch 8] [--config paper|smoke]
       [--variant V ...] [--steps 5]
Without --data, 48 samples at 640x480 are rendered with Mitsuba into a temporary folder first.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import torch
from harness import parser, run_script
from harness.pose import loader_rate, paper_dataset, process_rate

from posenet.config import load_config
from posenet.data import open_split
from posenet.models import create_model
from posenet.training.train import compared_layouts, make_optimizer, pm_loss_points, train_step, worker_init
from scgen.run.runner import RenderJob, run_render


def step_time(
    data: Path,
    config: str,
    variant: str | None,
    steps: int,
    layout: torch.memory_format,
    device: torch.device,
) -> tuple[float, int]:
    """(seconds per training step, batch size) for `config`'s model (or `variant`) and batch on `device`,
    weights and input images in memory format `layout`."""
    cfg = load_config(config, variant=variant)
    mc = cfg.model_config()
    ds = open_split(data, "train", cfg.data, mc, train=True)
    bs = cfg.optim.batch_size
    items = [ds[(0, i % len(ds))] for i in range(bs)]
    batch = {k: torch.stack([it[k] for it in items]).to(device) for k in items[0]}
    batch["roi_img"] = batch["roi_img"].contiguous(memory_format=layout)
    model = create_model(cfg.variant, cfg.preset, **cfg.model).to(device, memory_format=layout).train()
    opt, _ = make_optimizer(model, cfg.optim, total_iters=steps + 2)
    pm = pm_loss_points(ds.obj, device)
    times = []
    for _ in range(steps + 2):
        tic = time.perf_counter()
        train_step(model, opt, batch, pm, cfg)
        if device.type == "cuda":
            torch.cuda.synchronize()
        times.append(time.perf_counter() - tic)
    return sum(times[2:]) / steps, bs


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--samples", type=int, default=300, help="Samples timed per measurement.")
    ap.add_argument(
        "--config", default=None, help="Model/batch for the step time [paper on GPU, smoke on CPU]."
    )
    ap.add_argument("--batch", type=int, default=8, help="Loader batch size (the paper trains with 24).")
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--variant", action="append", help="Step time of this variant (repeatable).")
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    data = args.data
    if data is None:
        data = Path(tempfile.mkdtemp()) / "ds"
        run_render(RenderJob(out=data, n=48, backend="mitsuba", quality="draft"), progress=False)
    config = args.config or ("paper" if torch.cuda.is_available() else "smoke")
    threads = torch.get_num_threads()
    worker_init(0)  # one thread, as in a loader process (and OpenCV's pool stays unused before the fork)
    ds = paper_dataset(data)
    print(f"loader, 1 process (paper augmentations, 256/64): {process_rate(ds, args.samples):6.1f} samples/s")
    rate = loader_rate(ds, args.workers, args.samples, args.batch)
    print(f"loader, {args.workers} worker processes, batches of {args.batch}:  {rate:6.1f} samples/s")
    torch.set_num_threads(threads)
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    dev = torch.cuda.get_device_name() if device.type == "cuda" else "cpu"
    for variant in args.variant or [None]:
        name = f"{config} config" + (f", {variant}" if variant else "")
        for layout, what in compared_layouts(device):
            sec, bs = step_time(data, config, variant, args.steps, layout, device)
            print(
                f"train step ({name}, batch {bs}, {dev}, {what}): "
                f"{1000 * sec:.1f} ms ({bs / sec:.1f} samples/s)"
            )


if __name__ == "__main__":
    run_script(run, parse_args())
