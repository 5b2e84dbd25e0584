"""Training the detector: the train split, selected on val, in a run folder like pose training's.

OUT holds config.yaml, train_log.jsonl, tb/, last.pt (rewritten every ckpt_every epochs and at the stop) and
best.pt: the checkpoint with the highest val mean IoU so far (misses count 0) with the box it learns (bbox_obj
clipped to the image; bbox_visib's beside it, posenet.detection.detect.box_scores), scored whenever last.pt is
written; with several objects (`obj_ids`) the val figures pool every object's images (class_box_scores), and
the checkpoint names its classes (`obj_ids`: class k + 1 is the k-th). Without a val split (or no image
in it), best.pt is not written. With `minutes`, the schedule is fitted while it runs to end after that
much wall time, as pose training's (posenet.training.budget).
"""

from __future__ import annotations

import math
import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import torch
import yaml
from torch.utils.data import DataLoader
from torchvision.models.detection import FCOS

from posenet.checkpoint import save_checkpoint
from posenet.data import EpochSampler
from posenet.data.layout import split_scenes
from posenet.detection.detect import class_box_scores, detect, detector_obj_ids
from posenet.detection.detector import (
    DetectionDataset,
    DetectorConfig,
    build_detector,
    collate,
    image_groups,
)
from posenet.errors import PosenetError
from posenet.training.budget import TimeBudget, run_budget
from posenet.training.train import (
    LAST,
    RunLog,
    check_run_folder,
    checkpoint_due,
    loader_processes,
    loader_workers,
    make_optimizer,
    memory_format,
    pin_cpu_threads,
    resumed_state,
    stop_step,
)
from scgen.io import ScgenError, atomic_write_text, first_missing

BEST = "best.pt"


def train_detector(
    data: Path,
    out: Path,
    cfg: DetectorConfig,
    resume: bool = False,
    max_steps: int | None = None,
    minutes: float | None = None,
) -> Path:
    """Train on `data`'s train split into `out` on the current device; returns the path of last.pt. A run
    that fails before its first checkpoint (an image that cannot be read) leaves no folder behind."""
    budget = run_budget(minutes, cfg.optim.anneal_point, resume, max_steps)
    check_run_folder(out, resume)
    made = first_missing(out)
    try:
        return _train(data, out, cfg, resume, max_steps, budget)
    except (PosenetError, ScgenError):
        if made is not None and not (out / LAST).exists():
            shutil.rmtree(made, ignore_errors=True)
        raise


def _train(
    data: Path, out: Path, cfg: DetectorConfig, resume: bool, max_steps: int | None, budget: TimeBudget | None
) -> Path:
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    o = cfg.optim
    classes = cfg.classes()
    train_set = DetectionDataset(image_groups(data, "train", classes), cfg, train=True, seed=o.seed)
    per_epoch = len(train_set) // o.batch_size
    if per_epoch == 0:
        raise PosenetError(f"{len(train_set)} training images are fewer than one batch of {o.batch_size}")
    val = _val_images(data, classes)
    total = o.epochs * per_epoch
    state = resumed_state(out, "detector") if resume else None
    if state is not None:  # a resumed run keeps the schedule it started with (a time budget's fitted one)
        total = int(state.get("schedule_steps") or total)
    stop = budget.total if budget else stop_step(total, max_steps, o.epochs, per_epoch, announce=True)
    if device.type == "cpu":
        pin_cpu_threads(o.threads)
    torch.manual_seed(o.seed)
    # channels-last weights make every convolution's output channels-last on a CPU (FCOS batches the images)
    model = build_detector(cfg.model_dict(), cfg.pretrained, len(classes)).to(
        device, memory_format=memory_format(device)
    )
    optimizer, scheduler = make_optimizer(model, o, (lambda: budget.total) if budget else total)
    step, best = 0, -math.inf
    if state is not None:
        if state["model_config"] != cfg.model_dict() or detector_obj_ids(state) != classes:
            raise PosenetError(f"{out / LAST} is from another detector configuration")
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        scheduler.load_state_dict(state["scheduler"])
        step, best = int(state["step"]), float(state["best_val_iou"])
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "config.yaml", yaml.safe_dump(cfg.to_dict(), sort_keys=False))
    log = RunLog(out, step, None if budget else stop, o.log_every)
    try:
        stream = _batches(train_set, step, per_epoch, cfg, device)
        while step < stop:
            period = (step, stop, per_epoch)
            step, stop = _steps(model, optimizer, scheduler, stream, period, cfg, device, log, budget)
            schedule = budget.total if budget else total
            best = _save(out, model, optimizer, scheduler, cfg, (step, schedule), best, val, device, log)
    finally:
        log.close()
    return out / LAST


def _val_images(data: Path, obj_id: int | list[int]) -> list | None:
    """The val split's images showing the object(s), or None when the dataset has no val split. A val
    image that is not whole is refused as scan_split refuses it for every command, not dropped from
    validation."""
    return (image_groups(data, "val", obj_id) or None) if split_scenes(data, "val") else None


def _batches(
    dataset: DetectionDataset, step: int, per_epoch: int, cfg: DetectorConfig, device: torch.device
) -> Iterator:
    """The shuffled batches from `step` on, epoch after epoch (a fixed permutation per (seed, epoch),
    posenet.data.EpochSampler), read by persistent loader processes that read ahead across the epochs'
    ends: `cfg.workers`, on a CPU no more than the training threads leave cores for (loader_workers)."""
    o = cfg.optim
    sampler = EpochSampler(len(dataset), o.batch_size, seed=o.seed)
    sampler.set_epoch(*divmod(step, per_epoch))
    loader = DataLoader(
        dataset,
        batch_size=o.batch_size,
        sampler=sampler,
        collate_fn=collate,
        **loader_processes(loader_workers(cfg.workers, device)),
    )
    return iter(loader)


def _steps(
    model: FCOS,
    optimizer: torch.optim.Optimizer,
    scheduler: torch.optim.lr_scheduler.LambdaLR,
    stream: Iterator,
    period: tuple[int, int, int],
    cfg: DetectorConfig,
    device: torch.device,
    log: RunLog,
    budget: TimeBudget | None,
) -> tuple[int, int]:
    """One optimisation step per batch of `stream` from `period`'s (step, stop step, steps per epoch) up to
    the next checkpoint (every ckpt_every epochs) or the stop step; returns the step reached and the stop
    step (a time budget moves it after every step)."""
    step, stop, per_epoch = period
    model.train()
    tic = time.perf_counter()
    for images, targets in stream:
        wait = time.perf_counter() - tic  # the host idle for the loader since the last step
        lr = optimizer.param_groups[0]["lr"]
        terms = detector_step(model, optimizer, images, targets, device)
        scheduler.step()
        epoch = step // per_epoch
        step += 1
        toc = time.perf_counter()
        loss = sum(terms.values())
        times = {"step_s": toc - tic, "wait_s": wait, "images": len(images)}  # as pose training logs them
        log.step({"step": step, "epoch": epoch, "lr": lr, "loss": loss, **times, **terms})
        tic = toc
        if budget is not None:
            stop = _follow_budget(budget, step, toc, log)
        if step >= stop or checkpoint_due(step, cfg.optim, per_epoch):
            break
    return step, stop


def _follow_budget(budget: TimeBudget, step: int, now: float, log: RunLog) -> int:
    """Refit the schedule to the time budget after `step`; returns the step to stop at."""
    if budget.update(step, now):
        log.bar.write(f"time budget {budget.seconds / 60:g} min: schedule fitted to {budget.total} steps")
    if budget.fitted:
        log.bar.total = budget.total
    return step if budget.expired(now) and step < budget.total else budget.total


def detector_step(
    model: FCOS,
    optimizer: torch.optim.Optimizer,
    images: list[torch.Tensor],
    targets: list[dict[str, torch.Tensor]],
    device: torch.device,
) -> dict[str, float]:
    """One optimisation step on a batch (FCOS's summed losses); returns each loss term."""
    losses = model([i.to(device) for i in images], [{k: v.to(device) for k, v in t.items()} for t in targets])
    optimizer.zero_grad(set_to_none=True)
    sum(losses.values()).backward()
    optimizer.step()
    return {k: float(v.detach()) for k, v in losses.items()}


def _save(
    out: Path,
    model: FCOS,
    optimizer: torch.optim.Optimizer,
    scheduler: torch.optim.lr_scheduler.LambdaLR,
    cfg: DetectorConfig,
    steps: tuple[int, int],
    best: float,
    val: list | None,
    device: torch.device,
    log: RunLog,
) -> float:
    """Write last.pt at (step, the schedule's total steps), and best.pt when the val mean IoU beats
    `best`; returns the best so far."""
    step, schedule = steps
    metrics: dict[str, Any] = {}
    if val is not None:
        dets = detect(model, DetectionDataset(val, cfg, train=False), device)
        metrics = class_box_scores(dets, val, cfg.classes())
        for k in ("mean_iou", "ap50", "misses", "visib_mean_iou", "visib_ap50"):
            log.tb.add_scalar(f"val/{k}", metrics[k], step)
        log.bar.write(f"step {step}: val mean IoU {metrics['mean_iou']:.3f} (bbox_visib "
                      f"{metrics['visib_mean_iou']:.3f}), AP50 {metrics['ap50']:.3f}")  # fmt: skip
    improved = val is not None and metrics["mean_iou"] > best
    best = metrics["mean_iou"] if improved else best
    state = {
        "model": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "scheduler": scheduler.state_dict(),
        "step": step,
        "schedule_steps": schedule,
        "model_config": cfg.model_dict(),
        "config": cfg.to_dict(),
        "obj_ids": cfg.classes(),
        "val": metrics,
        "best_val_iou": best,
    }
    save_checkpoint(out / LAST, state)
    if improved:
        save_checkpoint(out / BEST, state)
    return best
