"""Training: Ranger (RAdam + Lookahead), warmup + flat + cosine per iteration, checkpoints, resume, DDP.

Run as `posenet train` (one process) or under `torchrun --nproc-per-node N` (DDP: NCCL on GPUs, gloo on
CPU). The batch size in the config is global and split over the processes. Every step appends one line
to OUT/train_log.jsonl; OUT/last.pt is rewritten after each epoch and when --max-steps stops the run.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import torch
import torch.distributed as dist
from timm.optim import param_groups_weight_decay
from torch.nn.parallel import DistributedDataParallel
from torch.optim.lr_scheduler import LambdaLR
from torch.utils.data import DataLoader
from torch.utils.tensorboard import SummaryWriter
from tqdm import tqdm

import posenet
from posenet.checkpoint import check_model_config, load_checkpoint, save_checkpoint
from posenet.config import OptimConfig, TrainConfig, config_from_dict
from posenet.data import EpochSampler, PoseDataset, open_split
from posenet.data.cache import BatchLoader, cache_loader
from posenet.data.camera import training_camera
from posenet.data.layout import scan_split
from posenet.data.object_model import ObjectModel
from posenet.errors import PosenetError
from posenet.models import PoseNet, create_model
from posenet.training.amp import Precision
from posenet.training.budget import PROBE_STEPS, TimeBudget, run_budget
from posenet.training.capture import Losses, compiled_losses, eager_losses
from posenet.training.fast_path import resolve_fast_paths
from posenet.training.losses import LOSS_TERMS, PmObject
from posenet.training.ranger import Ranger
from scgen.io import (
    ScgenError,
    atomic_write_text,
    check_output,
    first_missing,
    remove_stale_temporaries,
    usable_cores,
)

LOG_FILE = "train_log.jsonl"
LAST = "last.pt"


def lr_factor(it: int, total: int, o: OptimConfig) -> float:
    """GDRNPP's flat_and_anneal: linear warmup from warmup_factor, flat, cosine to 0 from anneal_point."""
    warm = 1.0
    if it < o.warmup_iters:
        alpha = it / o.warmup_iters
        warm = o.warmup_factor * (1 - alpha) + alpha
    start = o.anneal_point * total
    if it < start or total <= start:
        return warm
    return warm * 0.5 * (1 + math.cos(math.pi * (it - start) / (total - start)))


def steps_per_epoch(n_instances: int, o: OptimConfig, world: int = 1) -> int:
    """Optimisation steps per epoch over `n_instances` (EpochSampler drops an incomplete global batch)."""
    steps = EpochSampler(n_instances, o.batch_size // world, world).steps_per_epoch
    if steps == 0:
        raise PosenetError(f"{n_instances} training samples are fewer than one batch of {o.batch_size}")
    return steps


def cpu_threads(threads: int) -> int:
    """The intra-op threads that `threads` asks for: itself, or for 0 OMP_NUM_THREADS where it is set to a
    positive count (as a job script that shares a node sets it, and as torch's own default reads it),
    else one per core."""
    if threads:
        return threads
    env = os.environ.get("OMP_NUM_THREADS", "").strip()
    return int(env) if env.isdigit() and int(env) > 0 else usable_cores()


def pin_cpu_threads(threads: int) -> None:
    """Fix the intra-op thread count (`cpu_threads`) and make torch pick deterministic kernels.

    The float summation order depends on the thread count, and any code in the process may have changed
    it (e.g. `posenet bench --threads`), so training sets it itself: same config and seed, same losses.
    """
    torch.set_num_threads(cpu_threads(threads))
    torch.use_deterministic_algorithms(True, warn_only=True)
    # which also fills every new tensor with NaN, a debugging aid for code that reads memory it never
    # wrote: ~2,300 fills a smoke step, 8 % of it on 2 cores (418 -> 385 ms, median of 8 interleaved
    # rounds); no kernel here reads what it did not write, so the losses are the same bits without them
    torch.utils.deterministic.fill_uninitialized_memory = False


def worker_init(_: int) -> None:
    """One thread per loader process: the processes themselves are the parallelism."""
    torch.set_num_threads(1)
    cv2.setNumThreads(1)


def before_loader_fork() -> None:
    """Make this process safe to fork loader processes from: OpenCV's thread pool does not survive a fork.
    Once this process has used the pool (cv2.GaussianBlur, say, in an augmentation chain run here), a
    forked loader process hangs for ever in worker_init's cv2.setNumThreads. With one OpenCV thread here
    there is no pool to inherit; the training process itself runs no OpenCV while its loaders read."""
    cv2.setNumThreads(1)


def loader_workers(
    workers: int, device: torch.device, threads: int | None = None, cores: int | None = None
) -> int:
    """The loader processes a run starts for `data.workers`: all of them beside a GPU; on a CPU only as many
    as the `cores` (default: this machine's) that the training's `threads` leave free (default: this
    process's intra-op threads times torchrun's local processes); with none free, the training process
    loads its own batches. A loader process on a core the step's threads use costs the step more than the
    loading it does: OpenMP's threads meet at every operator, so one preempted thread stalls the others.
    Smoke preset, 2 cores, 2 threads (`posenet train --max-steps 150`, median step after step 30, 4
    alternated rounds): 208 ms a step with 2 loader processes, 189 ms loading in the training process
    (its 19 ms included); the same losses."""
    if device.type != "cpu":
        return workers
    if threads is None:
        threads = torch.get_num_threads() * int(os.environ.get("LOCAL_WORLD_SIZE", "1"))
    return max(0, min(workers, (cores or usable_cores()) - threads))


def loader_processes(workers: int) -> dict[str, Any]:
    """DataLoader arguments for `workers` persistent single-threaded loader processes (kept over the
    epochs' ends: the samplers' streams run on), with this process made safe to fork them from."""
    if workers > 0:
        before_loader_fork()
    return {"num_workers": workers, "persistent_workers": workers > 0, "worker_init_fn": worker_init}


def checkpoint_due(step: int, o: OptimConfig, per_epoch: int) -> bool:
    """Whether `step` ends a checkpoint period: every `o.ckpt_every` epochs of `per_epoch` steps."""
    return step % (o.ckpt_every * per_epoch) == 0


def make_optimizer(
    model: torch.nn.Module, o: OptimConfig, total_iters: int | Callable[[], int]
) -> tuple[torch.optim.Optimizer, LambdaLR]:
    """Ranger (posenet.training.ranger: RAdam + Lookahead as one fused Adam pass) and the per-iteration
    warmup + flat + cosine schedule over `total_iters` steps (a callable: read at every step, for a
    schedule fitted while it runs)."""
    # timm's no-decay group for biases and 1-d (norm) weights, unless they decay too (the groups timm's
    # create_optimizer_v2 made; its own keyword for the choice exists only in timm >= 1.0.26)
    params = model.parameters() if o.decay_norms_biases else param_groups_weight_decay(model, o.weight_decay)
    optimizer = Ranger(params, lr=o.lr, weight_decay=o.weight_decay, eps=o.eps)
    total = total_iters if callable(total_iters) else lambda: total_iters
    return optimizer, LambdaLR(optimizer, lambda it: lr_factor(it, total(), o))


@torch.no_grad()
def centralize_gradients(optimizer: torch.optim.Optimizer) -> None:
    """Ranger's gradient centralisation (GDR-Net's default `use_gc`): the gradient of every parameter
    with more than one dimension (conv and FC weights) minus its mean over all but the output dimension."""
    for group in optimizer.param_groups:
        for p in group["params"]:
            if p.grad is not None and p.grad.dim() > 1:
                p.grad.sub_(p.grad.mean(dim=tuple(range(1, p.grad.dim())), keepdim=True))


def _init_distributed() -> tuple[int, int, torch.device]:
    """(rank, world size, device) from torchrun's environment; a single process without it."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    cuda = torch.cuda.is_available()
    if world > 1 and not dist.is_initialized():
        dist.init_process_group("nccl" if cuda else "gloo")
    rank = dist.get_rank() if world > 1 else 0
    if cuda:
        local = int(os.environ.get("LOCAL_RANK", "0"))
        torch.cuda.set_device(local)
        return rank, world, torch.device("cuda", local)
    return rank, world, torch.device("cpu")


def memory_format(device: torch.device) -> torch.memory_format:
    """How training lays out the network's weights and input images: channels-last on a CPU, where
    oneDNN's NHWC convolutions make the smoke preset's step faster (240 -> 185 ms on 2 threads, batch 8:
    `python benchmarks/posenet_dataloader.py --data DIR`) and the CPU detector's (603 -> 460 ms:
    `python benchmarks/probes/detector_step.py --data DIR`); the default elsewhere (unmeasured)."""
    return torch.channels_last if device.type == "cpu" else torch.contiguous_format


def compared_layouts(device: torch.device) -> list[tuple[torch.memory_format, str]]:
    """Training's memory format, then the default contiguous one where that differs, each with a label:
    what the speed benchmarks time side by side."""
    trained = memory_format(device)
    layouts = [trained] + ([torch.contiguous_format] if trained != torch.contiguous_format else [])
    return [(f, str(f).removeprefix("torch.") + (" (training's)" if f == trained else "")) for f in layouts]


def _to(batch: dict[str, torch.Tensor], device: torch.device) -> dict[str, torch.Tensor]:
    """The batch on `device`, its input images in the training memory format."""
    moved = {k: v.to(device, non_blocking=True) for k, v in batch.items()}
    moved["roi_img"] = moved["roi_img"].contiguous(memory_format=memory_format(device))
    return moved


class RunLog:
    """Rank 0's step log (JSONL), TensorBoard scalars and progress bar."""

    def __init__(self, out: Path, step: int, total: int | None, every: int) -> None:
        path = out / LOG_FILE
        kept = (
            [ln for ln in path.read_text().splitlines() if json.loads(ln)["step"] <= step]
            if path.exists()
            else []
        )
        atomic_write_text(path, "".join(ln + "\n" for ln in kept))
        self.file = path.open("a")
        self.tb = SummaryWriter(str(out / "tb"))
        self.bar = tqdm(total=total, initial=step, desc="train", unit="step", dynamic_ncols=True)
        self.every = every
        self.window: list[dict[str, Any]] = []  # the rows since the rate was last shown

    def step(self, row: dict[str, Any]) -> None:
        self.file.write(json.dumps(row) + "\n")
        self.file.flush()
        self.bar.update(1)
        self.window.append(row)
        if len(self.window) >= self.every:
            rate, bound = throughput(self.window)
            self.bar.set_postfix(
                loss=f"{row['loss']:.4f}", epoch=row["epoch"], samples_s=f"{rate:.0f}", bound=bound
            )
            self.tb.add_scalar("samples_s", rate, row["step"])
            self.window = []
        if row["step"] % self.every == 0:
            for key, value in row.items():
                if key not in ("step", "epoch"):
                    self.tb.add_scalar(
                        key if key in ("lr", "loss", "step_s", "wait_s", "images") else f"loss/{key}",
                        value,
                        row["step"],
                    )

    def close(self) -> None:
        self.file.close()
        self.tb.close()
        self.bar.close()


def throughput(rows: list[dict[str, Any]]) -> tuple[float, str]:
    """Samples a second over logged rows (all processes' images over the wall time), and which stage bounds
    it: `loader` when the host spent over half that time waiting for batches, else `step`."""
    seconds = sum(r["step_s"] for r in rows)
    waited = sum(r["wait_s"] for r in rows)
    return sum(r["images"] for r in rows) / max(seconds, 1e-9), "loader" if waited > seconds / 2 else "step"


def pm_loss_points(obj: ObjectModel, device: torch.device) -> PmObject:
    """The point-matching loss's view of the object on `device`: its model points scaled by its largest
    extent, and its symmetries."""
    return PmObject(
        points=torch.from_numpy(obj.pm_points / obj.extent.max()).float().to(device),
        symmetries=torch.from_numpy(obj.symmetries).float().to(device),
    )


def train_step(
    model: torch.nn.Module,
    optimizer: torch.optim.Optimizer,
    batch: dict[str, torch.Tensor],
    pm: PmObject,
    cfg: TrainConfig,
    precision: Precision | None = None,
    losses: Losses | None = None,
) -> torch.Tensor:
    """One optimisation step in `precision` (default float32) through `losses` (default eager_losses; a
    run with optim.compile passes its compiled_losses); returns the detached float32 (total, *terms)
    losses. fp16 scales the loss (GradScaler); gradient centralisation sees the unscaled gradients."""
    precision = precision or Precision("off", batch["roi_img"].device)
    loss, values = (losses or eager_losses(model, pm, cfg.loss, precision))(batch)
    optimizer.zero_grad(set_to_none=True)
    precision.scaler.scale(loss).backward()
    if cfg.optim.grad_centralization:
        precision.scaler.unscale_(optimizer)
        centralize_gradients(optimizer)
    precision.scaler.step(optimizer)
    precision.scaler.update()
    return values


def train(
    data: Path,
    out: Path,
    cfg: TrainConfig,
    resume: bool = False,
    max_steps: int | None = None,
    minutes: float | None = None,
) -> Path:
    """Train on `data`'s train split into `out`; returns the path of the last checkpoint. With `minutes`,
    the schedule is fitted to end when that much wall time has passed since this call
    (posenet.training.budget)."""
    budget = run_budget(minutes, cfg.optim.anneal_point, resume, max_steps)
    rank, world, device = _init_distributed()
    made = first_missing(out)  # removed if the run fails before its first checkpoint
    try:
        run = _set_up(data, out, cfg, resume, max_steps, rank, world, device, budget)
        # a time budget's length is known once fitted
        log = _open_run_folder(out, cfg, run.step, None if budget else run.stop) if rank == 0 else None
        try:
            _loop(run, out / LAST if rank == 0 else None, log)
        finally:
            if log is not None:
                log.close()
        return out / LAST
    except (PosenetError, ScgenError):
        # a sample that cannot be read: a run folder this call made holds nothing to resume, so it goes
        if rank == 0 and made is not None and not (out / LAST).exists():
            shutil.rmtree(made, ignore_errors=True)
        raise
    finally:
        if world > 1:
            dist.destroy_process_group()


@dataclass
class _Run:
    """One process's training run: what the loop advances and the checkpoint saves."""

    cfg: TrainConfig
    model: PoseNet
    net: torch.nn.Module  # the model, or its DDP wrapper: what the steps call
    optimizer: torch.optim.Optimizer
    scheduler: LambdaLR
    dataset: PoseDataset
    sampler: EpochSampler
    loader: DataLoader
    pm: PmObject
    device: torch.device
    precision: Precision
    world: int
    workers: int  # loader processes (loader_workers)
    step: int  # optimisation steps done
    stop: int  # the step this invocation stops at
    budget: TimeBudget | None = None  # --minutes: the schedule's total, fitted while the run goes
    losses: Losses | None = None  # optim.compile: the compiled forward and losses (else eager, per step)
    weight_spread: float = 0.0  # largest weight difference between DDP processes, measured at the stop
    startup: StartUp | None = None  # rank 0: where the set-up's seconds went, printed with the first step


class StartUp:
    """Where a run's first minutes go: each set-up phase's seconds (`lap`), then the first step's wait for
    the loader (its processes starting) and its compute; rank 0 prints them."""

    def __init__(self) -> None:
        self.begin = self.last = time.perf_counter()
        self.phases: dict[str, float] = {}
        if posenet.IMPORT_SECONDS is not None:  # the `posenet` command: its imports came first
            self.phases["imports (torch, timm)"] = posenet.IMPORT_SECONDS
            self.begin -= posenet.IMPORT_SECONDS

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.phases[name] = now - self.last
        self.last = now

    def line(self) -> str:
        spent = ", ".join(f"{k} {v:.1f} s" for k, v in self.phases.items())
        return f"start-up {time.perf_counter() - self.begin:.1f} s: {spent}"


def _set_up(
    data: Path,
    out: Path,
    cfg: TrainConfig,
    resume: bool,
    max_steps: int | None,
    rank: int,
    world: int,
    device: torch.device,
    budget: TimeBudget | None = None,
) -> _Run:
    """Refuse a bad request, then open the data and build the seeded model, optimizer and loader
    (resumed from OUT/last.pt with `resume`); nothing is written. With a `budget`, the schedule's total
    is the budget's, refitted as the run goes."""
    cfg, paths = resolve_fast_paths(cfg, device, world)
    o = cfg.optim
    clock = StartUp()
    _refuse(out, o, resume, world)
    dataset = open_split(data, "train", cfg.data, cfg.model_config(), train=True, seed=o.seed)
    clock.lap("data (scan, object model)")
    state = resumed_state(out, "pose") if resume else None
    # a resumed run keeps the schedule it started with (a time budget's fitted one included)
    total = (state or {}).get("schedule_steps") or o.epochs * steps_per_epoch(len(dataset), o, world)
    sampler = EpochSampler(len(dataset), o.batch_size // world, world, rank, o.seed)
    stop = (
        budget.total if budget else stop_step(total, max_steps, o.epochs, sampler.steps_per_epoch, rank == 0)
    )
    model, optimizer, scheduler = _build(cfg, (lambda: budget.total) if budget else total, device)
    precision = Precision(o.amp, device)
    step = (
        _restore(state, out / LAST, model, optimizer, scheduler, precision, cfg.data.obj_id) if state else 0
    )
    clock.lap("network" + (f" and {LAST}" if state else ""))
    workers = loader_workers(cfg.data.workers, device)
    run_pm = pm_loss_points(dataset.obj, device)
    if rank == 0:
        for line in summary_lines(data, cfg, len(dataset), sampler.steps_per_epoch, total, step, stop, device,
                                  precision, world, budget, workers):  # fmt: skip
            tqdm.write(line)
        tqdm.write(paths)
    run = _Run(
        cfg=cfg,
        model=model,
        net=DistributedDataParallel(model) if world > 1 else model,
        optimizer=optimizer,
        scheduler=scheduler,
        dataset=dataset,
        sampler=sampler,
        pm=run_pm,
        loader=_loader(dataset, sampler, workers, device, data if cfg.data.loader == "cache" else None),
        workers=workers,
        device=device,
        precision=precision,
        world=world,
        step=step,
        stop=stop,
        budget=budget,
        losses=compiled_losses(model, run_pm, cfg.loss, precision, device) if o.compile else None,
    )
    clock.lap("loader")
    run.startup = clock if rank == 0 else None
    return run


def summary_lines(
    data: Path,
    cfg: TrainConfig,
    n_train: int,
    per_epoch: int,
    total: int,
    step: int,
    stop: int,
    device: torch.device,
    precision: Precision,
    world: int,
    budget: TimeBudget | None,
    workers: int,
) -> list[str]:
    """What a run is about to do, before its first step: the images per split, steps per epoch, the
    schedule, the device, its `workers` loader processes (`loader_workers`) and precision."""
    o, d = cfg.optim, cfg.data
    counts = []
    for split in ("val", "test"):
        try:
            counts.append(f"{split} {len({i.im_id for i in scan_split(data, split, d.obj_id)})}")
        except PosenetError:
            counts.append(f"{split} none")
    schedule = (
        f"fitted to {budget.seconds / 60:g} min while it runs"
        if budget
        else f"{o.epochs} epochs = {total} steps"
    )
    threads = torch.get_num_threads() if device.type == "cpu" else None
    return [
        f"data: {n_train} training instances of object {d.obj_id} in {data} (train split; "
        + ", ".join(counts)
        + " images, not read in training)",
        f"schedule: batch {o.batch_size}, {per_epoch} steps per epoch, {schedule}, lr {o.lr:g} (warmup "
        f"{o.warmup_iters} steps, cosine from {o.anneal_point:.0%}); "
        + (f"resuming at step {step}, " if step else "")
        + ("this run stops at the budget" if budget else f"this run stops at step {stop}"),
        f"device: {device.type}"
        + (f" ({threads} threads)" if threads else "")
        + f", {workers} loader processes ({d.loader} path"
        + (
            f"; data.workers {d.workers} would share the training threads' cores"
            if workers < d.workers
            else ""
        )
        + ")"
        + (f", {world} DDP processes" if world > 1 else "")
        + f"; precision: {precision.label} (optim.amp {o.amp})"
        + (
            f"; step compiled ({'CUDA graphs' if device.type == 'cuda' else 'inductor'})" if o.compile else ""
        ),
    ]


def _refuse(out: Path, o: OptimConfig, resume: bool, world: int) -> None:
    """A global batch that does not split over the processes, a compiled step under DDP (its gradient
    hooks inside CUDA graphs: not built), or a run folder that cannot be used."""
    if o.batch_size % world:
        raise PosenetError(f"batch size {o.batch_size} does not split over {world} processes")
    if o.compile and world > 1:
        raise PosenetError(f"optim.compile trains in one process, not {world} DDP processes")
    check_run_folder(out, resume)


def resumed_state(out: Path, kind: str) -> dict[str, Any]:
    """The run folder's checkpoint to resume (of `kind`: pose or detector), once read, with the
    temporaries a killed write left beside it removed (`last.pt.tmp-PID`: the run that resumes is the
    folder's only writer)."""
    state = load_checkpoint(out / LAST, kind=kind)
    remove_stale_temporaries(out)
    return state


def check_run_folder(out: Path, resume: bool) -> None:
    """The output rule for a run folder (pose or detector): one that can be made (scgen.io.check_output);
    an existing run is only resumed, and a new run starts in an empty or absent folder."""
    check_output(out, folder=True, overwrite=True, what="--out")
    if resume or not out.is_dir():
        return
    if (out / LAST).exists():
        raise PosenetError(f"{out} already holds a run ({LAST}); pass --resume or choose another --out")
    if any(out.iterdir()):
        raise PosenetError(f"--out {out} is not empty and holds no run ({LAST}): choose another --out")


def _loader(
    dataset: PoseDataset,
    sampler: EpochSampler,
    workers: int,
    device: torch.device,
    cache_root: Path | None = None,
) -> DataLoader | BatchLoader:
    """Batches in the sampler's order; `workers` persistent single-threaded processes. With `cache_root`
    (data.loader 'cache'), from the packed cache there, augmented on `device` (posenet.data.cache)."""
    args = {**loader_processes(workers), "pin_memory": device.type == "cuda"}
    if cache_root is not None:
        return cache_loader(cache_root, dataset, sampler, args, device)
    return DataLoader(dataset, batch_size=sampler.batch_size, sampler=sampler, **args)


def stop_step(total: int, max_steps: int | None, epochs: int, per_epoch: int, announce: bool) -> int:
    """The step to stop at: the schedule's end, or --max-steps before it (a cap past it is announced)."""
    if max_steps is None:
        return total
    if announce and max_steps > total:
        tqdm.write(
            f"note: --max-steps {max_steps} exceeds the schedule's {total} steps "
            f"({epochs} epochs x {per_epoch}); training stops at step {total}. "
            "Raise --epochs to train longer."
        )
    return min(total, max_steps)


def _build(
    cfg: TrainConfig, total: int | Callable[[], int], device: torch.device
) -> tuple[PoseNet, torch.optim.Optimizer, LambdaLR]:
    """The network from the run's seed (threads pinned on CPU: reproducible losses), its optimizer and
    the schedule over `total` steps."""
    if device.type == "cpu":
        pin_cpu_threads(cfg.optim.threads)
    torch.manual_seed(cfg.optim.seed)
    model = create_model(cfg.variant, cfg.preset, **cfg.model).to(device, memory_format=memory_format(device))
    optimizer, scheduler = make_optimizer(model, cfg.optim, total)
    return model, optimizer, scheduler


def _restore(
    state: dict[str, Any],
    path: Path,
    model: PoseNet,
    optimizer: torch.optim.Optimizer,
    scheduler: LambdaLR,
    precision: Precision,
    obj_id: int,
) -> int:
    """Load checkpoint `state` (read from `path`) of the same network configuration and object into the
    run; returns its step."""
    check_model_config(state, model.config_dict(), path)
    trained = config_from_dict(state["config"]).data.obj_id
    if trained != obj_id:
        raise PosenetError(f"{path} trains object {trained}, not object {obj_id} (--obj-id)")
    model.load_state_dict(state["model"])
    optimizer.load_state_dict(state["optimizer"])
    scheduler.load_state_dict(state["scheduler"])
    if state.get("grad_scaler"):  # an fp16 run's loss scale
        precision.scaler.load_state_dict(state["grad_scaler"])
    return int(state["step"])


def _checkpoint(run: _Run) -> dict[str, Any]:
    """What OUT/last.pt holds: weights, optimizer and schedule state, step, both configs, object size."""
    return {
        "model": run.model.state_dict(),
        "optimizer": run.optimizer.state_dict(),
        "scheduler": run.scheduler.state_dict(),
        "step": run.step,
        "schedule_steps": run.budget.total if run.budget else None,  # a time budget's fitted schedule
        "model_config": run.model.config_dict(),
        "config": run.cfg.to_dict(),
        "world_size": run.world,
        "rank_weight_spread": run.weight_spread,
        "amp": run.precision.mode,
        "grad_scaler": run.precision.scaler.state_dict(),
        # what `posenet predict` needs without the dataset: the object's mesh and the training camera
        "object": run.dataset.obj.to_record(),
        "camera": _camera_record(run.dataset.instances),
    }


def _camera_record(instances: list) -> dict[str, Any]:
    camera, uniform = training_camera([i.K for i in instances], instances[0].image_size)
    return {**camera.to_dict(), "uniform": uniform}


def _open_run_folder(out: Path, cfg: TrainConfig, step: int, stop: int | None) -> RunLog:
    """Rank 0: create OUT, write the resolved config.yaml and open the step log from `step`."""
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "config.yaml", cfg.to_yaml())
    return RunLog(out, step, stop, cfg.optim.log_every)


def _loop(run: _Run, ckpt: Path | None, log: RunLog | None) -> None:
    """Steps until the stop step, on one stream of batches that runs on over the epochs' ends (the
    loader reads ahead across them); with `ckpt` (rank 0), save it every ckpt_every epochs and at the
    stop."""
    if run.step >= run.stop:
        return
    run.model.train()
    run.sampler.set_epoch(*divmod(run.step, run.sampler.steps_per_epoch))
    for done, due in _steps(run, log):
        if done and run.world > 1:  # every process, before rank 0 saves
            run.weight_spread = rank_weight_spread(run.model)
            if ckpt is not None:
                tqdm.write(f"DDP: {run.world} processes, largest weight difference: {run.weight_spread:.1e}")
        if ckpt is not None and due:
            save_checkpoint(ckpt, _checkpoint(run))


def _follow_budget(run: _Run, log: RunLog | None) -> None:
    """Refit the schedule to the time budget after a step and stop at its end; under DDP every process
    takes rank 0's total and stop, so all keep one schedule."""
    budget, now = run.budget, time.perf_counter()
    assert budget is not None
    froze = budget.update(run.step, now)
    stop = run.step if budget.expired(now) and run.step < budget.total else budget.total
    if run.world > 1:
        shared = torch.tensor([budget.total, stop], dtype=torch.int64, device=run.device)
        dist.broadcast(shared, 0)
        budget.total, stop = (int(v) for v in shared.tolist())
    run.stop = stop
    if log is None:
        return
    if budget.fitted:
        log.bar.total = run.stop
    if froze:
        step_s = (now - budget.start) / run.step
        tqdm.write(
            f"time budget {budget.seconds / 60:g} min: schedule fitted to {budget.total} steps, cosine "
            f"from step {run.step} ({step_s:.3f} s per step so far, start-up included)"
        )
    elif stop < budget.total:
        fit = (
            f"of the fitted {budget.total}"
            if budget.fitted
            else f"before the fit (after {PROBE_STEPS} steps)"
        )
        tqdm.write(f"time budget spent at step {run.step} {fit}: stopping")


def rank_weight_spread(model: torch.nn.Module) -> float:
    """The largest difference of any weight between the DDP processes: 0 while DDP keeps them in sync
    (same initial weights, all-reduced gradients, the same optimiser steps)."""
    flat = torch.cat([p.detach().float().flatten() for p in model.parameters()])
    high, low = flat.clone(), flat.clone()
    dist.all_reduce(high, op=dist.ReduceOp.MAX)
    dist.all_reduce(low, op=dist.ReduceOp.MIN)
    return float((high - low).max())


def _steps(run: _Run, log: RunLog | None) -> Iterator[tuple[bool, bool]]:
    """One optimisation step per batch of the stream up to the stop step, yielding after each whether it
    was the last and whether a checkpoint is due (the last, or every ckpt_every epochs). Losses are
    averaged over the processes and logged with the images the step took over all processes (the global
    batch); they stay on the device and are read back every `optim.log_every` steps and before a
    checkpoint, all those steps' rows in one transfer: the host never waits for a step it has queued."""
    per_epoch = run.sampler.steps_per_epoch
    tic = time.perf_counter()
    pending: list[tuple[dict[str, Any], torch.Tensor]] = []  # logged rows whose losses are on the device
    for batch in run.loader:
        wait = time.perf_counter() - tic  # the host idle for the loader since the last step was queued
        if run.startup is not None:
            run.startup.lap(f"first batch {len(batch['roi_img'])} images ({run.workers} loader processes)")
        scale = run.precision.loss_scale()
        batch = _to(batch, run.device)
        values = train_step(run.net, run.optimizer, batch, run.pm, run.cfg, run.precision, run.losses)
        if run.startup is not None:  # what the first minutes went on, once
            run.startup.lap("first step")
            tqdm.write(run.startup.line())
            run.startup = None
        lr = run.optimizer.param_groups[0]["lr"]
        if run.precision.loss_scale() >= scale:
            # the schedule follows the optimizer's updates: fp16's scaler skips the first ones while it
            # finds its scale (2^16 -> 2^8 on the amp test config), and the warmup starts at the first update
            run.scheduler.step()
        epoch = run.step // per_epoch
        run.step += 1
        if run.budget is not None:
            _follow_budget(run, log)
        # (total, *terms, images): a fill on the device, not a copy from the host
        values = torch.cat([values, torch.full((1,), float(len(batch["roi_img"])), device=values.device)])
        if run.world > 1:
            dist.all_reduce(values)
            values[:-1] /= run.world
        done = run.step >= run.stop
        due = done or checkpoint_due(run.step, run.cfg.optim, per_epoch)
        if log is not None:
            toc = time.perf_counter()
            row = {"step": run.step, "epoch": epoch, "lr": lr, "step_s": toc - tic, "wait_s": wait}
            pending.append((row, values))
            if due or run.step % run.cfg.optim.log_every == 0:
                _write_rows(log, pending)
        yield done, due
        if done:
            return
        tic = time.perf_counter()


def _write_rows(log: RunLog, pending: list[tuple[dict[str, Any], torch.Tensor]]) -> None:
    """Log the pending steps' rows, their (total, *terms, images) read back in one transfer; empties
    `pending`."""
    if not pending:
        return
    read = torch.stack([values for _, values in pending]).tolist()
    for (row, _), (*losses, images) in zip(pending, read, strict=True):
        log.step(row | dict(zip(("loss", *LOSS_TERMS), losses, strict=True)) | {"images": int(images)})
    pending.clear()
