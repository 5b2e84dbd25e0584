"""posenet's throughput in one table: the loader, the training step, `posenet train` end to end and predict.

Stages, each written to --json as soon as it is measured (a killed run keeps what it measured):
  1. loader: training samples/s of one process, then of a DataLoader with --workers processes (the
     paper's augmentations at 256/64, as benchmarks/posenet_dataloader.py measures them);
  2. train step of --config (or each --variant), random init, in training's precision and memory format:
     the step as posenet trains it (fused Ranger, losses read back every log_every steps) and, on a
     CPU, 3a10b4b's step beside it (timm's Lookahead(RAdam), every step's losses read back at once),
     timed in alternating blocks in one process, with their ratio (and each --candidate config's step
     in the same blocks, with 3a10b4b's step of --config over it: what less arithmetic would buy); on
     CUDA the step captured as `optim.compile` does (torch.compile mode="reduce-overhead": CUDA graphs)
     beside the eager one. Printed as
     `train step (CONFIG, batch B, DEVICE, ...): X ms (Y samples/s)`, posenet_dataloader.py's form;
  3. the optimizer step alone on that model, timm's against posenet's (same gradients);
  4. `posenet train` itself for --train-steps steps: samples/s from its own log (loader waits included),
     the first --skip steps (start-up, compilation) left out, on CUDA also with optim.compile and with
     data.loader and optim.compile `auto` (last: what auto takes there, the packed cache and the compiled
     step, beside the default per-sample eager run); with
     --against TREE (a checkout of another commit, e.g. `git worktree add /tmp/old 3a10b4b`), `posenet
     train --config CONFIG` from this tree and from TREE in --rounds alternating rounds (3), each with its
     own package's defaults (OpenMP waiting included: the children get no GOMP_SPINCOUNT or
     OMP_WAIT_POLICY), and the ratio of their median steps;
  5. predict by stage on the train split's images at their ground-truth boxes, with the checkpoint that
     stage 4 wrote (decode, crop, pose network, solve; the detector only with --detector);
  6. with --detector, predict as `posenet predict --onnx --detector-onnx --batch B` runs it (both networks
     exported by `posenet export`, images decoded in threads) on --predict-data's train images, e.g. a
     640x480 render while --data is the 320x240 control set: images/s end to end and ms by stage.

Usage: python benchmarks/throughput.py [--data DIR] [--workers 2] [--batch 8] [--steps 5] [--samples 300]
       [--config paper|smoke] [--variant V ...] [--candidate CONFIG ...] [--train-steps 200]
       [--against TREE [--rounds 3]] [--predict 60] [--detector DET.pt [--onnx-batch 8]
       [--predict-data DS]] [--json FILE] [--gpu-check]
Without --data, 48 samples at 640x480 are rendered with Mitsuba into a temporary folder first. On a CPU
by default (config smoke); --gpu-check sizes every stage for one short run on a GPU node (paper config,
both variants, 14 loader processes, batch 24, 200 train steps each: about 5 minutes on one H200).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from harness import parser, run_script
from timm.optim import create_optimizer_v2

from posenet import OPENMP_WAITING
from posenet.config import TrainConfig, load_config
from posenet.data import open_split
from posenet.data.layout import scan_split
from posenet.models import create_model
from posenet.training.amp import Precision
from posenet.training.capture import compiled_losses
from posenet.training.losses import PmObject, pose_losses
from posenet.training.train import (
    LAST,
    LOG_FILE,
    loader_workers,
    make_optimizer,
    memory_format,
    pin_cpu_threads,
    pm_loss_points,
    train_step,
    worker_init,
)

GPU_CHECK = {"workers": 14, "batch": 24, "steps": 20, "samples": 1000, "train_steps": 200}
POSENET = [sys.executable, "-c", "from posenet.cli import main; main()"]  # the CLI, in a child process
BLOCKS = 3  # alternating blocks per compared step: old, new, old, new, ...

Step = Callable[[], torch.Tensor]


class Results:
    """The table's lines, printed as they come and kept in --json (rewritten after every line)."""

    def __init__(self, path: Path | None, header: dict[str, Any]) -> None:
        self.path, self.data = path, {"header": header, "rows": []}
        self.lines: list[str] = []

    def add(self, line: str, **values: Any) -> None:
        print(line, flush=True)
        self.lines.append(line)
        self.data["rows"].append({"line": line, **values})
        if self.path is not None:
            self.path.write_text(json.dumps(self.data, indent=1))


@dataclass
class Bench:
    """What every stage reads: the table it adds to, the data, the arguments, the device and its name."""

    res: Results
    data: Path
    args: argparse.Namespace
    device: torch.device
    dev: str


def timm_optimizer(model: torch.nn.Module, cfg: TrainConfig) -> torch.optim.Optimizer:
    """3a10b4b's optimizer: timm's Lookahead over torch's RAdam, as make_optimizer built it there."""
    o = cfg.optim
    return create_optimizer_v2(
        model,
        opt="lookahead_radam",
        lr=o.lr,
        weight_decay=o.weight_decay,
        betas=(0.95, 0.999),
        eps=o.eps,
        decoupled_weight_decay=True,
        filter_bias_and_bn=not o.decay_norms_biases,
    )


def step_setup(data: Path, cfg: TrainConfig, device: torch.device) -> tuple[dict, PmObject, Precision, int]:
    """One training batch on `device` (training's memory format), the point-matching object, the
    precision training resolves and the batch size."""
    mc = cfg.model_config()
    ds = open_split(data, "train", cfg.data, mc, train=True)
    bs = cfg.optim.batch_size
    items = [ds[(0, i % len(ds))] for i in range(bs)]
    batch = {k: torch.stack([it[k] for it in items]).to(device) for k in items[0]}
    batch["roi_img"] = batch["roi_img"].contiguous(memory_format=memory_format(device))
    return batch, pm_loss_points(ds.obj, device), Precision(cfg.optim.amp, device), bs


def fresh_model(cfg: TrainConfig, device: torch.device) -> torch.nn.Module:
    torch.manual_seed(cfg.optim.seed)
    model = create_model(cfg.variant, cfg.preset, **cfg.model)
    return model.to(device, memory_format=memory_format(device)).train()


def eager_step(cfg: TrainConfig, batch: dict, pm: PmObject, precision: Precision, old: bool) -> Step:
    """posenet's step (fused Ranger; the losses stay on the device) or 3a10b4b's (timm's optimizer,
    every step's losses read back to the host, as its training loop did)."""
    model = fresh_model(cfg, batch["roi_img"].device)
    opt = timm_optimizer(model, cfg) if old else make_optimizer(model, cfg.optim, 10**6)[0]

    def step() -> torch.Tensor:
        values = train_step(model, opt, batch, pm, cfg, precision)
        if old:
            values.tolist()
        return values

    return step


def captured_step(cfg: TrainConfig, batch: dict, pm: PmObject, precision: Precision) -> Step:
    """`posenet train`'s step with optim.compile: forward and losses (and through AOTAutograd the backward)
    compiled with mode="reduce-overhead", which records them as CUDA graphs and replays them; the fused
    optimizer runs eagerly after. Shapes are fixed (one batch), so the graphs are recorded once."""
    model = fresh_model(cfg, batch["roi_img"].device)
    opt, _ = make_optimizer(model, cfg.optim, 10**6)
    losses = compiled_losses(model, pm, cfg.loss, precision, batch["roi_img"].device)
    return lambda: train_step(model, opt, batch, pm, cfg, precision, losses)


def sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize()


def block_time(step: Step, steps: int, device: torch.device) -> float:
    """Seconds per step over `steps` steps run back to back, the device synchronised at the ends only."""
    sync(device)
    tic = time.perf_counter()
    for _ in range(steps):
        step()
    sync(device)
    return (time.perf_counter() - tic) / steps


def compare_steps(steps: dict[str, Step], n: int, device: torch.device, warm: int = 2) -> dict[str, float]:
    """Median seconds per step of each of `steps`, timed in BLOCKS alternating blocks of `n` steps after
    `warm` warm-up steps each (compilation, allocator), so that a machine's drift hits all alike."""
    for step in steps.values():
        for _ in range(warm):
            step()
    blocks: dict[str, list[float]] = {k: [] for k in steps}
    for _ in range(BLOCKS):
        for k, step in steps.items():
            blocks[k].append(block_time(step, n, device))
    return {k: statistics.median(v) for k, v in blocks.items()}


def optimizer_times(cfg: TrainConfig, batch: dict, pm: PmObject, n: int) -> dict[str, float]:
    """Median seconds of the optimizer step alone, timm's and posenet's, on gradients of one backward."""
    device = batch["roi_img"].device
    model = fresh_model(cfg, device)
    loss, _ = pose_losses(model(batch["roi_img"], batch["roi_coord2d"]), batch, pm, cfg.loss)
    loss.backward()
    opts = {
        "timm (3a10b4b)": timm_optimizer(model, cfg),
        "fused Ranger": make_optimizer(model, cfg.optim, 1)[0],
    }
    times: dict[str, list[float]] = {k: [] for k in opts}
    for _ in range(BLOCKS):
        for k, opt in opts.items():
            times[k].append(block_time(opt.step, n, device))
    return {k: statistics.median(v) for k, v in times.items()}


def train_rate(
    data: Path,
    config: TrainConfig | str,
    steps: int,
    skip: int,
    out: Path,
    tree: Path | None = None,
    against: bool = False,
) -> tuple[float, float]:
    """`posenet train` for `steps` steps in a child process, from this checkout or from source tree `tree`:
    (samples/s, seconds per step) from its log after the first `skip` steps. `config`: a config (written
    to a file) or a preset name or file as `--config` takes it. `against`: the child's environment
    without OPENMP_WAITING, so that each tree's posenet sets its own."""
    if not isinstance(config, str):
        out.with_suffix(".yaml").write_text(config.to_yaml())
        config = str(out.with_suffix(".yaml"))
    cmd = [*POSENET, "train", "--data", str(data)]
    cmd += ["--out", str(out), "--config", config, "--max-steps", str(steps)]
    env = None
    if tree is not None:  # first on the path, and the working folder (which `python -c` puts before it)
        env = {**os.environ, "PYTHONPATH": str(tree)}
    if against:  # each tree's own OpenMP waiting, not what importing this posenet put in the environment
        env = {k: v for k, v in (env or os.environ).items() if k not in OPENMP_WAITING}
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env=env, cwd=tree)
    rows = [json.loads(ln) for ln in (out / LOG_FILE).read_text().splitlines()][skip:]
    seconds = sum(r["step_s"] for r in rows)
    return sum(r["images"] for r in rows) / seconds, seconds / len(rows)


def predict_stages(
    data: Path, obj_id: int, ckpt: Path, detector: Path | None, device: torch.device, n: int
) -> dict[str, float]:
    """Milliseconds per image by predict's stages (decode timed here) on up to `n` train-split images at
    their ground-truth boxes (the detector's stage too when one is given), and images/s end to end."""
    from posenet.predict.predictor import Predictor  # scipy: a GPU node may lack it

    predictor = Predictor.load(ckpt, detector=detector, device=device)
    insts = scan_split(data, "train", obj_id)[:n]
    decode: list[float] = []
    tic = time.perf_counter()
    for i, inst in enumerate(insts):
        t0 = time.perf_counter()
        image = cv2.imread(str(inst.rgb), cv2.IMREAD_COLOR)
        decode.append(1000 * (time.perf_counter() - t0))
        if i == 0:  # warm-up: the first call's allocations and kernel choices stay out of the figures
            predictor(image, inst.K, None if detector else inst.bbox_obj)
            predictor.timings.ms.clear()
            decode.clear()
            tic = time.perf_counter()
            continue
        predictor(image, inst.K, None if detector else inst.bbox_obj)
    wall = time.perf_counter() - tic
    return {
        "decode": float(np.mean(decode)),
        **predictor.timings.per_image_ms(len(insts) - 1),
        "images_s": (len(insts) - 1) / wall,
    }


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--samples", type=int, default=300, help="Samples timed per loader measurement.")
    ap.add_argument("--config", default=None, help="Model/batch for the steps [paper on GPU, smoke on CPU].")
    ap.add_argument("--batch", type=int, default=8, help="Loader batch size (the paper trains with 24).")
    ap.add_argument("--steps", type=int, default=5, help="Steps per timed block of the step comparison.")
    ap.add_argument("--variant", action="append", help="Step time of this variant (repeatable).")
    ap.add_argument(
        "--candidate",
        action="append",
        default=[],
        help="On a CPU: this config's step (a preset or YAML/TOML file) in the same timed blocks, with "
        "3a10b4b's step of --config over it (repeatable).",
    )
    ap.add_argument("--train-steps", type=int, default=200, help="posenet train's steps (0: skip the stage).")
    ap.add_argument("--skip", type=int, default=20, help="posenet train's first steps left out of its rate.")
    ap.add_argument("--predict", type=int, default=60, help="Images predict runs on (0: skip the stage).")
    ap.add_argument("--detector", type=Path, default=None, help="A detector checkpoint for predict's stages.")
    ap.add_argument(
        "--onnx-batch",
        type=int,
        default=8,
        help="Stage 6's batch: predict through ONNX with --detector (0: skip the stage) [8].",
    )
    ap.add_argument(
        "--predict-data", type=Path, default=None, help="Stage 6's images: a dataset's train split [--data]."
    )
    ap.add_argument(
        "--against",
        type=Path,
        default=None,
        help="A source tree of another commit: posenet train from it and from this one, side by side.",
    )
    ap.add_argument("--rounds", type=int, default=BLOCKS, help=f"Alternating rounds of --against [{BLOCKS}].")
    ap.add_argument(
        "--threads",
        type=int,
        default=None,
        help="CPU threads of the steps [the config's optim.threads: 0, one a core].",
    )
    ap.add_argument("--json", type=Path, default=None, help="Write the table here after every line.")
    ap.add_argument("--gpu-check", action="store_true", help="Size the stages for one short GPU-node run.")
    args = ap.parse_args()
    if args.gpu_check:
        for k, v in GPU_CHECK.items():
            setattr(args, k, v)
        args.variant = args.variant or ["gdrnet", "gap-gdrnet"]
    return args


def run(args: argparse.Namespace) -> None:
    data = args.data
    if data is None:
        from scgen.run.runner import RenderJob, run_render  # a renderer: only where there is no --data

        data = Path(tempfile.mkdtemp()) / "ds"
        run_render(RenderJob(out=data, n=48, backend="mitsuba", quality="draft"), progress=False)
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    dev = torch.cuda.get_device_name() if device.type == "cuda" else "cpu"
    config = args.config or ("paper" if device.type == "cuda" else "smoke")
    header = {
        "device": dev,
        "torch": torch.__version__,
        "config": config,
        "args": {k: str(v) for k, v in vars(args).items()},
    }
    b = Bench(Results(args.json, header), data, args, device, dev)
    threads = torch.get_num_threads()
    process_line(b)
    torch.set_num_threads(threads)
    trained: list[tuple[TrainConfig, str, str | None]] = []  # what stage 4 trained, for the compiled runs
    for variant in args.variant or [None]:
        cfg = step_config(config, variant, args.threads)
        if device.type == "cpu":
            pin_cpu_threads(cfg.optim.threads)  # as training: one thread per core
        name = f"{config} config" + (f", {variant}" if variant else "")
        step_lines(b, cfg, name, {c: step_config(c, variant, cfg.optim.threads) for c in args.candidate})
        if args.train_steps:
            cfg.data.workers = args.workers
            cfg.optim.ckpt_every = 10**6  # last.pt once, at the stop: not every epoch of a small set
            with tempfile.TemporaryDirectory() as tmp:
                run = Path(tmp) / "run"
                if train_line(b, cfg, name, variant, run) and args.predict:
                    predict_line(b, cfg, run / LAST, name, variant)
                    if args.onnx_batch and args.detector:
                        onnx_predict_line(b, cfg, run / LAST, name, variant)
            trained.append((cfg, name, variant))
    if device.type == "cuda":  # posenet train with optim.compile (CUDA graphs), once the rest is written
        for cfg, name, variant in trained:
            cfg.optim.compile = True
            with tempfile.TemporaryDirectory() as tmp:
                train_line(b, cfg, name + ", optim.compile", variant, Path(tmp) / "run")
            # what `auto` takes on CUDA (the packed cache and the compiled step): the default-to-be
            # (posenet.training.fast_path), beside the per-sample eager line above
            cfg.data.loader, cfg.optim.compile = "auto", "auto"
            with tempfile.TemporaryDirectory() as tmp:
                train_line(b, cfg, name + ", data.loader and optim.compile auto", variant, Path(tmp) / "run")
    if args.against is not None and args.train_steps:
        against_line(b, config)
    print("\n".join(["", f"== throughput on {dev} ({config} config)", *b.res.lines]))


def train_line(b: Bench, cfg: TrainConfig, name: str, variant: str | None, run: Path) -> bool:
    """Stage 4: `posenet train` with `cfg` into `run`, its line; whether it trained."""
    args = b.args
    try:
        rate, sec = train_rate(b.data, cfg, args.train_steps, args.skip, run)
    except subprocess.CalledProcessError as exc:  # its output went to stderr above
        b.res.add(f"posenet train ({name}): failed ({exc})", stage="posenet train", variant=variant)
        return False
    started = loader_workers(args.workers, b.device)  # this process's threads are the child's
    b.res.add(
        f"posenet train ({name}, batch {cfg.optim.batch_size}, {b.dev}, {started} loader processes"
        + (f" of --workers {args.workers}" if started < args.workers else "")
        + f", steps {args.skip + 1}-{args.train_steps}): {1000 * sec:.1f} ms a step ({rate:.1f} samples/s)",
        stage="posenet train",
        variant=variant,
        compiled=cfg.optim.compile,
        loader=cfg.data.loader,
        ms=1000 * sec,
        samples_s=rate,
    )
    return True


def against_line(b: Bench, config: str) -> None:
    """Stage 4 side by side: `posenet train --config CONFIG` from this tree and from --against, in
    --rounds alternating rounds; their median seconds a step and the ratio."""
    args = b.args
    trees = {"this tree": None, str(args.against): args.against.resolve()}
    times: dict[str, list[float]] = {k: [] for k in trees}
    for _ in range(args.rounds):
        for label, tree in trees.items():
            with tempfile.TemporaryDirectory() as tmp:
                times[label].append(
                    train_rate(b.data, config, args.train_steps, args.skip, Path(tmp) / "run", tree, True)[1]
                )
    (new, t_new), (old, t_old) = ((k, statistics.median(v)) for k, v in times.items())
    for label, sec in ((new, t_new), (old, t_old)):
        b.res.add(
            f"posenet train ({config} config, {b.dev}, steps {args.skip + 1}-{args.train_steps}, "
            f"from {label}): {1000 * sec:.1f} ms a step, median of {args.rounds} alternating rounds "
            f"({', '.join(f'{1000 * s:.0f}' for s in times[label])})",
            stage="posenet train against",
            tree=label,
            ms=1000 * sec,
        )
    b.res.add(
        f"  ratio: {old} / {new} = {t_old / t_new:.2f}", stage="posenet train ratio", ratio=t_old / t_new
    )


def predict_line(b: Bench, cfg: TrainConfig, ckpt: Path, name: str, variant: str | None) -> None:
    """Stage 5: predict by stage on the checkpoint stage 4 wrote (a line saying why where it cannot)."""
    detector = b.args.detector
    what = f"predict ({name}, {b.dev}, torch, " + ("detector" if detector else "ground-truth boxes") + ")"
    try:
        ms = predict_stages(b.data, cfg.data.obj_id, ckpt, detector, b.device, b.args.predict)
    except Exception as exc:  # scipy missing on a node, say: a line of the table, not the end of it
        b.res.add(f"{what}: not measured ({exc!r})"[:400], stage="predict", variant=variant)
        return
    stages = ", ".join(f"{k} {v:.1f}" for k, v in ms.items() if k != "images_s")
    b.res.add(
        f"{what}: {ms['images_s']:.1f} images/s; ms an image: {stages}",
        stage="predict",
        variant=variant,
        **ms,
    )


def onnx_predict_line(b: Bench, cfg: TrainConfig, ckpt: Path, name: str, variant: str | None) -> None:
    """Stage 6: predict as `posenet predict --onnx POSE.onnx --detector DET.onnx --batch B` runs it, on
    --predict-data's train images: both graphs exported from stage 4's checkpoint and --detector by
    `posenet export`, and a pose for every image (no minimum detector score)."""
    args = b.args
    data = args.predict_data or b.data
    what = f"predict ({name}, {b.dev}, onnx, detector, batch {args.onnx_batch}"
    try:
        from harness.predict import measure  # scipy: a GPU node may lack it

        from posenet.data.camera import read_camera_file
        from posenet.predict.batch import BatchPredictor
        from posenet.predict.predictor import Predictor

        paths = [inst.rgb for inst in scan_split(data, "train", cfg.data.obj_id)][: args.predict]
        camera = read_camera_file(data / "camera.json")
        with tempfile.TemporaryDirectory() as tmp:
            pose, detector = Path(tmp) / "pose.onnx", Path(tmp) / "detector.onnx"
            cmd = [*POSENET, "export", "--ckpt", str(ckpt)]
            cmd += ["--onnx", str(pose), "--detector", str(args.detector), "--detector-onnx", str(detector)]
            done = subprocess.run(cmd, capture_output=True, text=True)
            if done.returncode:
                raise RuntimeError(f"posenet export: {done.stderr.strip().splitlines()[-1:]}")
            predictor = Predictor.load(ckpt, detector, b.device, onnx=pose, min_score=0.0)
            batched = BatchPredictor(predictor, args.onnx_batch, detector)
            try:
                row, _ = measure(predictor, paths, camera, batched)
            finally:
                batched.close()
    except Exception as exc:  # onnxruntime missing, say: a line of the table, not the end of it
        b.res.add(f"{what}): not measured ({exc!r})"[:400], stage="predict onnx", variant=variant)
        return
    size = "x".join(map(str, camera.size))  # the dataset's images: its camera's
    stages = ", ".join(f"{k} {v:.1f}" for k, v in row["ms"].items())
    b.res.add(
        f"{what}, {len(paths)} images at {size}): {row['end_to_end']:.1f} images/s end to end; "
        f"ms an image: {stages}",
        stage="predict onnx",
        variant=variant,
        images=size,
        **row,
    )


def process_line(b: Bench) -> None:
    """Stage 1: the loader, one process and --workers processes."""
    try:
        from harness.pose import loader_rate, paper_dataset, process_rate  # scipy: a GPU node may lack it
    except ModuleNotFoundError as exc:
        b.res.add(f"loader: not measured ({exc})", stage="loader")
        return
    worker_init(0)  # one thread, as in a loader process (and OpenCV's pool stays unused before the fork)
    args = b.args
    ds = paper_dataset(b.data)
    rate = process_rate(ds, args.samples)
    b.res.add(
        f"loader, 1 process (paper augmentations, 256/64): {rate:.1f} samples/s",
        stage="loader",
        processes=1,
        samples_s=rate,
    )
    rate = loader_rate(ds, args.workers, args.samples, args.batch)
    b.res.add(
        f"loader, {args.workers} worker processes, batches of {args.batch}: {rate:.1f} samples/s",
        stage="loader",
        processes=args.workers,
        samples_s=rate,
    )


def step_config(name: str, variant: str | None, threads: int | None) -> TrainConfig:
    """A config (--config's or a --candidate's) as the steps run it: random init (no download, the same
    arithmetic), and `threads` intra-op threads where given."""
    cfg = load_config(name, variant=variant)
    cfg.model["pretrained"] = None
    if threads is not None:
        cfg.optim.threads = threads
    return cfg


def step_lines(b: Bench, cfg: TrainConfig, name: str, candidates: dict[str, TrainConfig]) -> None:
    """Stages 2 and 3: the step compared (old and new on a CPU, with any candidate configs' steps;
    eager and captured on CUDA), then the optimizer step alone."""
    res, data, device, dev, n = b.res, b.data, b.device, b.dev, b.args.steps
    batch, pm, precision, bs = step_setup(data, cfg, device)
    steps = {"eager (posenet)": eager_step(cfg, batch, pm, precision, old=False)}
    old = "eager, 3a10b4b's step (timm Ranger, per-step readback)"
    named = {label: f"eager (posenet), config {label}" for label in candidates}
    if device.type == "cpu":
        steps[old] = eager_step(cfg, batch, pm, precision, old=True)
    else:
        steps["captured (torch.compile reduce-overhead)"] = captured_step(cfg, batch, pm, precision)
    shown = {what: (bs, precision.label) for what in steps}  # each step's batch size and precision
    for label, candidate in candidates.items() if device.type == "cpu" else ():
        c_batch, c_pm, c_precision, c_bs = step_setup(data, candidate, device)
        steps[named[label]] = eager_step(candidate, c_batch, c_pm, c_precision, old=False)
        shown[named[label]] = (c_bs, c_precision.label)
    times: dict[str, float] = {}
    for what, step in steps.items():
        try:
            times |= compare_steps({what: step}, 1, device, warm=3)  # warm-up and compilation, each alone
        except Exception as exc:  # a step that cannot run here is a line of the table, not the end of it
            res.add(
                f"train step ({name}, batch {bs}, {dev}, {what}): failed: {exc!r}"[:400],
                stage="step",
                what=what,
            )
    times = compare_steps({k: steps[k] for k in times}, n, device, warm=0)
    for what, sec in times.items():
        size, label = shown[what]
        res.add(
            f"train step ({name}, batch {size}, {dev}, {label}, {what}): "
            f"{1000 * sec:.1f} ms ({size / sec:.1f} samples/s)",
            stage="step",
            what=what,
            ms=1000 * sec,
            samples_s=size / sec,
        )
    compared = [(k, t) for k, t in times.items() if k not in named.values()]  # --config's two steps
    if len(compared) == 2:
        (new, t_new), (old_step, t_old) = compared
        res.add(f"  ratio: {old_step} / {new} = {t_old / t_new:.2f}", stage="step ratio", ratio=t_old / t_new)
    for label, what in named.items():
        if what in times and old in times:
            ratio = times[old] / times[what]
            res.add(f"  ratio: {old} / {what} = {ratio:.2f}", stage="step ratio", candidate=label,
                    ratio=ratio)  # fmt: skip
    opt = optimizer_times(cfg, batch, pm, max(n, 5))
    res.add(
        f"optimizer step ({name}, {dev}): " + ", ".join(f"{k} {1000 * v:.1f} ms" for k, v in opt.items()),
        stage="optimizer",
        **{k: 1000 * v for k, v in opt.items()},
    )


if __name__ == "__main__":
    run_script(run, parse_args())
