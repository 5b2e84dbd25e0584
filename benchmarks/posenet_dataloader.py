"""posenet input pipeline and training step speed.

Prints (1) training samples/s of one loader process with the paper's augmentations (DZI, brightness/
contrast at p=0.8, background replacement at p=0.5) at the paper's 256/64 resolution, (2) the DataLoader
throughput with --workers processes, (3) the training step time (forward, losses, backward, Ranger step)
of --config (or each --variant) on the current device (paper on a GPU, smoke on a CPU by default), with
the weights and images in training's memory format (posenet.train.memory_format: channels-last on a CPU)
and, on a CPU, also in the default contiguous one, side by side.

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
from torch.utils.data import DataLoader

from posenet.config import load_config
from posenet.data import PoseDataset, open_split
from posenet.models import create_model
from posenet.train import compared_layouts, make_optimizer, pm_loss_points, train_step, worker_init
from scgen.run.runner import RenderJob, run_render


def paper_dataset(data: Path) -> PoseDataset:
    cfg = load_config("paper")
    return open_split(data, "train", cfg.data, cfg.model_config(), train=True)


def process_rate(ds: PoseDataset, n: int) -> float:
    """Training samples/s of one process (the work of one loader worker)."""
    for i in range(len(ds)):  # build the background pool and warm the file cache
        ds[(0, i)]
    tic = time.perf_counter()
    for k in range(n):
        ds[(1 + k // len(ds), k % len(ds))]
    return n / (time.perf_counter() - tic)


def loader_rate(ds: PoseDataset, workers: int, n: int, batch: int) -> float:
    """Samples/s through a training-like DataLoader (batches, `workers` processes), once warm.

    The keys run through several epochs in one pass: with a small benchmark dataset an epoch is one
    or two batches, and the loader would drain and restart at its first process every epoch.
    """
    warm = 2 * max(workers, 1) * batch  # two batches per process: all up, background pools built
    keys = [(1 + k // len(ds), k % len(ds)) for k in range(warm + n)]
    loader = DataLoader(ds, batch_size=batch, sampler=keys, num_workers=workers, worker_init_fn=worker_init)
    done, tic = 0, None
    for b in loader:
        done += len(b["key"])
        if tic is None and done == warm:
            tic, done = time.perf_counter(), 0
    return done / (time.perf_counter() - tic)


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--samples", type=int, default=300, help="Samples timed per measurement.")
    ap.add_argument(
        "--config", default=None, help="Model/batch for the step time [paper on GPU, smoke on CPU]."
    )
    ap.add_argument("--batch", type=int, default=8, help="Loader batch size (the paper trains with 24).")
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--variant", action="append", help="Step time of this variant (repeatable).")
    args = ap.parse_args()
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
    main()
