"""The `posenet` command line: parses options and calls the library; errors are one line, exit non-zero."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import click

import posenet
from clishell.group import OneLineErrorGroup
from clishell.types import FiniteFloatRange
from posenet.config import AMP_MODES, config_from_dict, load_config
from posenet.detection.options import MIN_SCORE
from posenet.doctor import check_config_packages
from posenet.errors import PosenetError
from posenet.evaluation.options import BATCH_SIZE, CALIBRATION_SPLIT
from posenet.models import VARIANTS
from posenet.navigation.config import NavConfig
from posenet.predict.options import FORMATS as PREDICT_FORMATS
from posenet.predict.options import LOW_CONFIDENCE, PREDICT_PASSES, SAME_CROP_IOU
from scgen.io import check_output, make_output_folder, preset_intrinsics, write_output

# Building this command line and answering --help load nothing heavier than the modules above: torch,
# timm, torchvision, OpenCV and the networks are imported inside each command, when it runs (a mistyped
# option answers at once; tests/test_cli_startup.py holds it).

PATH = click.Path(path_type=Path)

# posenet train's and train-detector's: both fit their schedule with posenet.training.budget
minutes_option = click.option(
    "--minutes",
    type=FiniteFloatRange(min=0, min_open=True),
    default=None,
    help="Wall-time budget: the schedule is fitted while it runs so that its cosine ends after M minutes "
    "(set-up included); the fitted steps are printed. A new run only: no --resume or --max-steps.",
)


def passes_option(default: int, why: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """posenet eval's and predict's --passes: both re-crop through posenet.predict.recrop."""
    return click.option(
        "--passes",
        type=click.IntRange(min=1),
        default=default,
        show_default=True,
        help="Pose network runs per image: 1 on the box, then each re-cropped around the model's box at the "
        f"pose before (posenet.predict.recrop); {why}",
    )


same_crop_option = click.option(
    "--same-crop-iou",
    type=FiniteFloatRange(0, 1, min_open=True),
    default=SAME_CROP_IOU,
    show_default=True,
    help="A pass after the first runs only where the model's box at the pose before overlaps the box that "
    "pass cropped around by less than this IoU (1: every pass runs; posenet.predict.recrop.next_crop).",
)


def filter_options(command: Callable[..., Any]) -> Callable[..., Any]:
    """eval's and predict's settings of the navigation filter (posenet.navigation.config.NavConfig); the
    process noise is in diameters of the target, so one default fits any model scale."""
    defaults = NavConfig()
    for name, attr, text in (
        ("--accel-noise", "accel_noise", "the acceleration it leaves out, sqrt PSD (diameters / s^1.5)"),
        ("--angular-accel-noise", "angular_accel_noise", "the angular one, sqrt PSD (rad / s^1.5)"),
    ):  # fmt: skip
        command = click.option(
            name, attr, type=FiniteFloatRange(min=0, min_open=True), default=getattr(defaults, attr),
            show_default=True, help=f"Navigation filter: {text}.",
        )(command)  # fmt: skip
    return command


@click.group(cls=OneLineErrorGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="scgen", prog_name="posenet")  # one distribution holds both packages
def main() -> None:
    """posenet: GDR-Net / GAP-GDRNet 6D pose networks trained and evaluated on scgen (BOP-layout) datasets."""


@main.command()
@click.option(
    "--data", type=PATH, required=True, help="Dataset folder (scgen output or BOP layout + xyz maps)."
)
@click.option(
    "--out", type=PATH, required=True, help="Run folder: config.yaml, last.pt, train_log.jsonl, tb/."
)
@click.option("--config", "config", default=None, help="paper | smoke | a YAML/TOML file  [default: paper]")
@click.option(
    "--variant", default=None, help="gdrnet (default), convnext, ggca, mecs, pgsa, afr, gap-gdrnet."
)
@click.option(
    "--epochs", type=click.IntRange(min=1), default=None, help="Override optim.epochs (sets the schedule)."
)
@click.option(
    "--max-steps", type=click.IntRange(min=1), default=None, help="Stop after N steps (schedule unchanged)."
)
@minutes_option
@click.option(
    "--resume", is_flag=True, help="Continue OUT/last.pt (with OUT/config.yaml unless --config is given)."
)
@click.option(
    "--obj-id",
    type=click.IntRange(min=1),
    default=None,
    help="Object to train on  [default: the config's data.obj_id, 1]",
)
@click.option(
    "--amp",
    default=None,
    help=f"Mixed precision, overriding optim.amp: {' | '.join(AMP_MODES)} (auto: bf16 on a CUDA GPU that "
    "has it, else float32).",  # checked with the config: a bad value is one line, as every other
)
def train(
    data: Path,
    out: Path,
    config: str | None,
    variant: str | None,
    epochs: int | None,
    max_steps: int | None,
    minutes: float | None,
    resume: bool,
    obj_id: int | None,
    amp: str | None,
) -> None:
    """Train on the dataset's train split (under torchrun: DDP over the processes)."""
    tic = time.perf_counter()
    from posenet.training.train import train as run_train

    posenet.IMPORT_SECONDS = time.perf_counter() - tic  # printed in train's start-up line
    if config is None:
        saved = out / "config.yaml"
        config = str(saved) if resume and saved.is_file() else "paper"
    cfg = load_config(config, variant=variant, epochs=epochs, obj_id=obj_id, amp=amp)
    check_config_packages(cfg)
    ckpt = run_train(data, out, cfg, resume=resume, max_steps=max_steps, minutes=minutes)
    if os.environ.get("RANK", "0") == "0":  # torchrun: one line, not one per process
        click.echo(f"checkpoint: {ckpt}")


@main.command("eval")
@click.option("--data", type=PATH, required=True, help="Dataset folder.")
@click.option(
    "--ckpt",
    type=PATH,
    required=True,
    multiple=True,
    help="Checkpoint. Repeatable: one per object (each scored on its own object, then overall), or "
    "checkpoints compared with --by-factor.",
)
@click.option("--split", default="test", show_default=True)
@click.option(
    "--boxes", type=PATH, default=None, help="Stored detection boxes (BOP JSON); default: GT boxes."
)
@click.option(
    "--json", "json_path", type=PATH, default=None, help="Write the summary (or factor table) as JSON."
)
@click.option("--predictions", type=PATH, default=None, help="Per-instance JSONL [default: next to --json].")
@click.option(
    "--by-factor", type=PATH, default=None, help="Sample-groups file: per-group ADD@0.02 m (Table 5)."
)
@click.option("--workers", type=click.IntRange(min=0), default=2, show_default=True, help="Loader processes.")
@click.option(
    "--batch-size",
    type=click.IntRange(min=1),
    default=BATCH_SIZE,
    show_default=True,
    help="RoIs per forward (the results do not depend on it; latency is timed apart at batch 1).",
)
@click.option(
    "--obj-id",
    type=click.IntRange(min=1),
    default=None,
    help="Object to evaluate  [default: the one the checkpoint was trained on]",
)
@click.option("--bop-csv", type=PATH, default=None, help="Also write the estimates as a BOP19 results CSV.")
@click.option(
    "--pnp",
    type=click.Choice(["patch", "ransac", "both"]),
    default="patch",
    show_default=True,
    help="Pose solver: the network's Patch-PnP, OpenCV's PnP-RANSAC on its predicted xyz and mask, or both.",
)
@passes_option(1, "eval gives the box IoU with the true box per pass; 1 is the paper's protocol.")
@same_crop_option
@filter_options
@click.option("--overwrite", is_flag=True, help="Replace an existing --json, --predictions or --bop-csv.")
def eval_cmd(
    data: Path,
    ckpt: tuple[Path, ...],
    split: str,
    boxes: Path | None,
    json_path: Path | None,
    predictions: Path | None,
    by_factor: Path | None,
    workers: int,
    batch_size: int,
    obj_id: int | None,
    bop_csv: Path | None,
    pnp: str,
    passes: int,
    same_crop_iou: float,
    accel_noise: float,
    angular_accel_noise: float,
    overwrite: bool,
) -> None:
    """Rotation/translation error, ADD@0.02 m, ADD@0.1d (and what the rotation and the translation each
    score alone), ADD-S@0.1d, MSSD, ESA score and batch-1 latency.

    For an object with symmetries (models_info), ADD is ADD-S and the rotation error is also given as
    the smallest over the symmetric poses of the ground truth. With --pnp both, each figure is given for
    Patch-PnP and PnP-RANSAC side by side. On a split of rendezvous sequences, a table per sequence adds
    its error along time and the frame-to-frame jitter of the estimate beside the truth's (--json:
    `sequences`), and, where the checkpoint's noise is calibrated (posenet calibrate), the navigation
    filter's and smoother's figures beside the per-frame ones (--json: `navigation`).
    """
    from posenet.checkpoint import load_checkpoint
    from posenet.evaluation.evaluate import by_factor as run_by_factor
    from posenet.evaluation.evaluate import (
        by_factor_table,
        evaluate_pnp,
        format_table,
        json_record,
        summary_rows,
    )
    from posenet.evaluation.sequences import per_sequence, sequence_table
    from posenet.predict.ransac import PNP_LABELS, PNP_METHODS
    from scgen.io import bop

    methods = PNP_METHODS if pnp == "both" else (pnp,)
    if bop_csv is not None and len(methods) > 1:
        raise PosenetError("--bop-csv writes the estimates of one PnP method: --pnp patch or --pnp ransac")
    if by_factor is not None and (bop_csv is not None or predictions is not None):
        given = "--bop-csv" if bop_csv is not None else "--predictions"
        raise PosenetError(f"--by-factor writes a per-group table (--json), not {given}: run eval without "
                           f"--by-factor for the estimates")  # fmt: skip
    if by_factor is not None and passes > 1:
        raise PosenetError("--passes re-crops the estimates of one evaluation: run eval without --by-factor")
    if by_factor is None and len(ckpt) > 1 and (obj_id is not None or len(methods) > 1):
        raise PosenetError("several --ckpt score one object each: give no --obj-id, and one --pnp method")
    for c in ckpt:  # every checkpoint, of the right kind, before any work
        load_checkpoint(c, kind="pose")
    for path in (json_path, predictions, bop_csv):
        if path is not None:
            check_output(path, folder=False, overwrite=overwrite)
    if by_factor is None and predictions is None:  # the default: replaced when there, as the user named none
        predictions = json_path.with_suffix(".predictions.jsonl") if json_path else ckpt[0].with_name(
            f"predictions_{split}.jsonl")  # fmt: skip
        check_output(predictions, folder=False, overwrite=True)
    if by_factor is not None:
        res = run_by_factor(data, list(ckpt), by_factor, split, boxes, workers, batch_size, obj_id, methods)
        click.echo(f"boxes: {res['boxes']}")
        click.echo(by_factor_table(res))
        if json_path is not None:
            write_output(json_path, json.dumps(res, indent=2) + "\n")
        return
    if len(ckpt) > 1:
        kw = {"workers": workers, "batch_size": batch_size, "passes": passes, "same_crop_iou": same_crop_iou}
        eval_objects(data, ckpt, split, boxes, json_path, predictions, bop_csv, methods[0], **kw)
        return
    results = evaluate_pnp(data, ckpt[0], methods, split, boxes, workers=workers, batch_size=batch_size,
                           obj_id=obj_id, passes=passes, same_crop_iou=same_crop_iou)  # fmt: skip
    variant, summaries = results[methods[0]].variant, [r.summary for r in results.values()]
    click.echo(f"boxes: {summaries[0]['boxes']}")
    columns = ["value"] if methods == ("patch",) else [PNP_LABELS[m] for m in methods]
    rows = summary_rows(summaries, keys=set().union(*summaries))
    click.echo(format_table([f"{variant} on {split}", *columns], rows))
    click.echo(  # under the table, which stays right under its boxes line
        "crop box IoU with bbox_obj, per pass: " + ", ".join(f"{v:.3f}" for v in summaries[0]["box_iou"])
    )
    for m, figures in per_sequence(data, split, results).items():  # a sequence dataset: the tracker baseline
        results[m].summary["sequences"] = figures
        click.echo(sequence_table(figures, f"sequence ({PNP_LABELS[m]})" if len(methods) > 1 else "sequence"))
    if results[methods[0]].summary.get("sequences") is not None:
        nav_config = replace(NavConfig(), accel_noise=accel_noise, angular_accel_noise=angular_accel_noise)
        navigation_summary(data, split, ckpt[0], results[methods[0]], nav_config)
    records = [{**json_record(r), "pnp": m} for m, res in results.items() for r in res.records]
    write_output(predictions, "".join(json.dumps(r) + "\n" for r in records))
    if json_path is not None:
        body = summaries[0] if len(methods) == 1 else {m: r.summary for m, r in results.items()}
        write_output(json_path, json.dumps({"variant": variant, "split": split, **body}, indent=2) + "\n")
    click.echo(f"predictions: {predictions}")
    if bop_csv is not None:
        write_output(bop_csv, bop.results_csv(results[methods[0]].records))
        click.echo(f"BOP results: {bop_csv}")


def eval_objects(
    data: Path,
    ckpts: tuple[Path, ...],
    split: str,
    boxes: Path | None,
    json_path: Path | None,
    predictions: Path,
    bop_csv: Path | None,
    method: str,
    **kw: Any,
) -> None:
    """`posenet eval` of one checkpoint per object: a column per object and one overall
    (instance-weighted), every object's records in --predictions and --bop-csv."""
    from posenet.evaluation.evaluate import (
        evaluate_objects,
        format_table,
        json_record,
        overall_summary,
        summary_rows,
    )
    from scgen.io import bop

    results = evaluate_objects(data, ckpts, method, split=split, boxes=boxes, **kw)
    per_object = {k: r.summary for k, r in results.items()}
    overall = overall_summary(list(per_object.values()))
    click.echo(f"boxes: {overall['boxes']}")
    variants = "/".join(sorted({r.variant for r in results.values()}))
    header = [f"{variants} on {split}", *(f"obj {k}" for k in per_object), "all"]
    click.echo(format_table(header, summary_rows([*per_object.values(), overall], keys=set(overall))))
    records = [r for res in results.values() for r in res.records]
    write_output(predictions, "".join(json.dumps({**json_record(r), "pnp": method}) + "\n" for r in records))
    if json_path is not None:
        objects = [{"obj_id": k, "variant": r.variant, **r.summary} for k, r in results.items()]
        body = {"split": split, "objects": objects, "overall": overall}
        write_output(json_path, json.dumps(body, indent=2) + "\n")
    click.echo(f"predictions: {predictions}")
    if bop_csv is not None:
        write_output(bop_csv, bop.results_csv(records))
        click.echo(f"BOP results: {bop_csv}")


@main.command("train-detector")
@click.option("--data", type=PATH, required=True, help="Dataset folder (train split trained, val selects).")
@click.option("--out", type=PATH, required=True, help="Run folder: config.yaml, last.pt, best.pt, tb/.")
@click.option(
    "--config",
    "config",
    default=None,
    help="cpu (alias smoke) | light (for frame rate) | paper | a YAML/TOML file  [default: cpu]",
)
@click.option("--max-steps", type=click.IntRange(min=1), default=None, help="Stop after N steps.")
@minutes_option
@click.option("--resume", is_flag=True, help="Continue OUT/last.pt (with OUT/config.yaml unless --config).")
@click.option(
    "--obj-id",
    type=click.IntRange(min=1),
    default=None,
    help="Detect this object alone (one class)  [default: every object of the dataset's models_info]",
)
def train_detector_cmd(
    data: Path,
    out: Path,
    config: str | None,
    max_steps: int | None,
    minutes: float | None,
    resume: bool,
    obj_id: int | None,
) -> None:
    """Train the detector on the box the pose network is cropped around: FCOS on the whole object's box
    clipped to the image (bbox_obj, amodal; the cpu, light and paper presets), one class per object of the
    dataset (or --obj-id's alone), or `arch: mask-timm` on one object's mask (`mask`; the box is its
    extent). Backbones start from ImageNet (`pretrained:` imagenet, package, a local file or null)."""
    from posenet.data.layout import object_ids
    from posenet.detection.detector import load_detector_config
    from posenet.detection.train import BEST, train_detector

    if config is None:
        saved = out / "config.yaml"
        config = str(saved) if resume and saved.is_file() else "cpu"
    cfg = load_detector_config(config, obj_id, object_ids(data))
    last = train_detector(data, out, cfg, resume=resume, max_steps=max_steps, minutes=minutes)
    best = last.with_name(BEST)
    click.echo(f"checkpoint: {last}")
    if best.is_file():
        click.echo(f"best on val: {best} (the one for posenet boxes / predict --detector)")
    else:
        click.echo(f"no {BEST}: the dataset has no val images to select on; give {last.name} to --detector")


@main.command()
@click.option("--data", type=PATH, required=True, help="Dataset folder.")
@click.option("--out", type=PATH, required=True, help="Box file to write (BOP detection JSON).")
@click.option("--split", default="test", show_default=True)
@click.option("--detector", type=PATH, default=None, help="Detector checkpoint; default: GT boxes.")
@click.option("--noise", type=FiniteFloatRange(min=0), default=0.0, show_default=True,
              help="Relative std of centre shift and log size change (0: exact GT boxes).")  # fmt: skip
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--obj-id", type=click.IntRange(min=1), default=1, show_default=True, help="Object to box.")
@click.option("--overwrite", is_flag=True, help="Replace an existing --out.")
def boxes(
    data: Path,
    out: Path,
    split: str,
    detector: Path | None,
    noise: float,
    seed: int,
    obj_id: int,
    overwrite: bool,
) -> None:
    """Write one box per image of a split: the detector's (misses recorded), else the GT full-object boxes,
    optionally perturbed. Every kind is the box the pose network is cropped around, bbox_obj (the whole
    object's box): exact (it may reach past the image), perturbed or detected (clipped to the image)."""
    from posenet.data.boxes import boxes_from_gt
    from posenet.data.layout import scan_split

    check_output(out, folder=False, overwrite=overwrite)
    if detector is not None and noise > 0:
        raise PosenetError("--noise perturbs the ground-truth boxes: it takes no --detector")
    if detector is None:
        insts = [i for i in scan_split(data, split, obj_id) if i.px_count_visib > 0]
        entries = boxes_from_gt(insts, noise, seed)
        label = (
            f"perturbed ground-truth bbox_obj (--noise {noise:g}, seed {seed}; clipped to the image)"
            if noise > 0
            else "ground-truth bbox_obj (the whole object's box; it may reach past the image)"
        )
    else:
        import torch

        from posenet.detection.detect import detect_split, detection_entries

        device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
        _, dets, _ = detect_split(detector, data, split, obj_id, device)
        entries = detection_entries(dets, obj_id, f"detector:{detector}")
        label = f"detector ({sum(d.box is None for d in dets)} misses; bbox_obj clipped to the image)"
    write_output(out, json.dumps(entries) + "\n")
    click.echo(f"{len(entries)} {label} boxes -> {out}")


@main.command("bench")
@click.option(
    "--variant",
    "variants",
    multiple=True,
    type=click.Choice(list(VARIANTS)),
    help="Variant to bench (repeatable); default: all.",
)
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True)
@click.option("--warmup", type=click.IntRange(min=0), default=3, show_default=True, help="Untimed forwards.")
@click.option("--iters", type=click.IntRange(min=1), default=10, show_default=True, help="Timed forwards.")
@click.option("--threads", type=click.IntRange(min=1), help="CPU intra-op threads (default: torch's).")
@click.option("--smoke", is_flag=True, help="Bench the reduced-width CPU presets instead of the paper's.")
@click.option("--backbone", help="Any timm backbone with a stride-32 map, instead of the preset's.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Also write JSON.")
@click.option(
    "--onnx", is_flag=True, help="Also export each variant to ONNX and time it in onnxruntime (CPU)."
)
@click.option("--overwrite", is_flag=True, help="Replace an existing --json.")
def bench(
    variants: tuple[str, ...],
    device: str,
    warmup: int,
    iters: int,
    threads: int | None,
    smoke: bool,
    backbone: str | None,
    json_path: Path | None,
    onnx: bool,
    overwrite: bool,
) -> None:
    """Params, MACs and batch-1 latency / FPS of the pose-network variants (architecture only, random
    init: no weights needed); with --onnx, onnxruntime's latency beside torch's."""
    import torch

    from posenet.export.bench import PAPER, device_label, format_report, resolve_device, run_bench

    if json_path:
        check_output(json_path, folder=False, overwrite=overwrite)
    if threads:
        torch.set_num_threads(threads)
    dev = resolve_device(device)
    rows = run_bench(list(variants or VARIANTS), dev, warmup, iters, smoke, backbone, onnx)
    label = device_label(dev)
    click.echo(format_report(rows, label, paper={} if smoke else PAPER))
    if json_path:
        payload = {"device": label, "variants": [asdict(r) for r in rows]}
        write_output(json_path, json.dumps(payload, indent=2) + "\n")


@main.command("export")
@click.option("--ckpt", type=PATH, required=True, help="Pose checkpoint (last.pt).")
@click.option("--onnx", "onnx_path", type=PATH, required=True, help="ONNX file to write.")
@click.option("--detector", type=PATH, default=None, help="Also a detector checkpoint, for posenet predict.")
@click.option("--detector-onnx", type=PATH, default=None, help="Where --detector's graph goes.")
@click.option("--overwrite", is_flag=True, help="Replace an existing --onnx file.")
def export_cmd(
    ckpt: Path, onnx_path: Path, detector: Path | None, detector_onnx: Path | None, overwrite: bool
) -> None:
    """Export a pose network to ONNX (opset 18, dynamic batch): inputs roi_img, roi_coord2d; outputs mask,
    xyz, region, rot6d, site. Checks onnxruntime's outputs against torch's on a random batch of 2. With
    --detector, also the detector's best box and score for one image of the pose network's training camera
    (what `posenet predict --onnx POSE.onnx --detector DET.onnx` runs)."""
    import torch
    from tqdm import tqdm

    from posenet.checkpoint import load_model
    from posenet.export.onnx_export import OPSET, export_onnx, max_difference, onnx_session

    if (detector is None) != (detector_onnx is None):
        raise PosenetError("--detector and --detector-onnx go together")
    check_output(onnx_path, folder=False, overwrite=overwrite)
    if detector_onnx is not None:
        check_output(detector_onnx, folder=False, overwrite=overwrite)
    model, state = load_model(ckpt, torch.device("cpu"))
    if detector is not None:
        export_detector_graph(detector, detector_onnx, state, ckpt)  # type: ignore[arg-type]
        click.echo(f"onnx: {detector_onnx} (the detector's best box, opset {OPSET})")
    with tqdm(total=2, desc="export", unit="stage", dynamic_ncols=True, leave=False) as bar:
        bar.set_postfix_str("tracing the network, writing the graph")
        export_onnx(model, onnx_path)
        bar.update()
        bar.set_postfix_str("onnxruntime against torch")
        diff = max_difference(model, onnx_session(onnx_path))
        bar.update()
    click.echo(f"onnx: {onnx_path} (opset {OPSET}, dynamic batch); max |onnxruntime - torch| = {diff:.2e}")


def export_detector_graph(detector: Path, path: Path, pose_state: dict, ckpt: Path) -> None:
    """The detector's DetectorBestBox graph at the size of the pose checkpoint's training camera."""
    import torch

    from posenet.detection.detect import load_detector
    from posenet.export.onnx_export import export_detector_onnx

    if "camera" not in pose_state:
        raise PosenetError(
            f"{ckpt} predates posenet predict (no training camera): retrain it to export --detector"
        )
    model, state = load_detector(detector, torch.device("cpu"))
    size = tuple(pose_state["camera"]["size"])
    export_detector_onnx(model, path, size, state["model_config"]["score_thresh"])


def navigation_summary(data: Path, split: str, ckpt: Path, result: Any, config: NavConfig) -> None:
    """eval's navigation table on a sequence split (per frame, filtered, smoothed), into the summary; a
    line saying how to get it where the checkpoint's noise is not calibrated."""
    from posenet.evaluation.evaluate import format_table
    from posenet.evaluation.navigation import NAVIGATION_LEGEND, navigate_split, navigation_table
    from posenet.navigation.noise import noise_path

    if not noise_path(ckpt).is_file():
        click.echo(f"navigation: calibrate the checkpoint's noise for the filtered and smoothed figures "
                   f"(posenet calibrate --data DATASET --ckpt {ckpt})")  # fmt: skip
        return
    nav = navigate_split(data, split, ckpt, result.records, config)
    if nav is None:
        return
    columns = {k: nav[k] for k in ("per_frame", "filtered", "smoothed")}
    click.echo(format_table(["navigation", "per frame", "filtered", "smoothed"], navigation_table(columns)))
    click.echo(NAVIGATION_LEGEND)
    result.summary["navigation"] = nav


@main.command()
@click.option("--data", type=PATH, required=True, help="Dataset folder with a labelled split.")
@click.option("--ckpt", type=PATH, required=True, help="Pose checkpoint; the noise is written beside it.")
@click.option(
    "--split", default=CALIBRATION_SPLIT, show_default=True, help="A split the network never trained on."
)
@click.option(
    "--boxes", type=PATH, default=None, help="Stored detection boxes (BOP JSON); default: GT boxes."
)
@passes_option(PREDICT_PASSES, "predict's default, which the tracker's measurements use.")
@same_crop_option
@click.option(
    "--min-confidence",
    type=FiniteFloatRange(0, 1),
    default=LOW_CONFIDENCE,
    show_default=True,
    help="A pose under this confidence is no measurement to the filter (a dark frame's guess): neither "
    "calibrated on nor used (the file keeps it).",
)
@click.option(
    "--sequences",
    type=PATH,
    default=None,
    help="A labelled sequence render (its --sequences-split): how much of the error persists from frame to "
    "frame, and for how long [default: --data itself, where it is a sequence dataset; else none measured].",
)
@click.option("--sequences-split", default="test", show_default=True, help="The split of --sequences.")
@click.option("--workers", type=click.IntRange(min=0), default=2, show_default=True, help="Loader processes.")
def calibrate(
    data: Path,
    ckpt: Path,
    split: str,
    boxes: Path | None,
    passes: int,
    same_crop_iou: float,
    min_confidence: float,
    sequences: Path | None,
    sequences_split: str,
    workers: int,
) -> None:
    """Measure the pose network's noise on labelled images, for the navigation filter: per band of the
    network's confidence, the covariance of its rotation and translation errors on --data's --split
    (robust: turned poses and lost boxes are the filter's gate's to reject), and along labelled sequences
    (--sequences) how much of an error persists from frame to frame and how long. Writes CKPT's stem +
    .noise.json beside it, which posenet predict --track and posenet eval read (docs/navigation.md)."""
    from posenet.checkpoint import load_checkpoint
    from posenet.evaluation.calibration import calibrate_noise
    from posenet.navigation.noise import noise_path

    load_checkpoint(ckpt, kind="pose")
    out = noise_path(ckpt)
    check_output(out, folder=False, overwrite=True)
    seq = (sequences, sequences_split) if sequences is not None else None
    model = calibrate_noise(data, ckpt, split, boxes, passes, workers, min_confidence, seq, same_crop_iou)
    click.echo(f"split '{split}' of {data}, {passes} pass(es):")
    click.echo(model.table())
    click.echo(f"wrote {write_output(out, model.to_json())}")


@main.command()
@click.option("--data", type=click.Path(path_type=Path), required=True, help="Dataset folder.")
@click.option(
    "--ckpt",
    "ckpts",
    type=click.Path(path_type=Path, exists=True),
    multiple=True,
    required=True,
    help="Checkpoint; repeat to compare models side by side.",
)
@click.option(
    "--samples", default=None, help="Comma-separated sample ids (im_id), e.g. 3,17,42 (without: lists them)."
)
@click.option("--split", default="test", show_default=True)
@click.option("--out", type=click.Path(path_type=Path), required=True, help="Folder for the PNGs.")
@click.option("--overwrite", is_flag=True, help="Write into an existing, non-empty --out.")
def viz(
    data: Path, ckpts: tuple[Path, ...], samples: str | None, split: str, out: Path, overwrite: bool
) -> None:
    """Pose overlays (predicted green vs GT white contour) and feature-response heat maps, as PNGs."""
    import cv2

    from posenet.checkpoint import load_checkpoint
    from posenet.data.layout import scan_split
    from posenet.evaluation.viz import heatmap_panel, overlay_panel

    check_output(out, folder=True, overwrite=overwrite)
    states = [load_checkpoint(c, kind="pose") for c in ckpts]
    if samples is None:
        obj_id = config_from_dict(states[0]["config"]).data.obj_id
        held = sorted({i.im_id for i in scan_split(data, split, obj_id)})
        shown = ",".join(map(str, held[:20])) + (f",... ({len(held)} in all)" if len(held) > 20 else "")
        raise PosenetError(f"give --samples: split '{split}' of {data} holds sample ids {shown or 'none'}")
    try:
        ids = [int(s) for s in samples.split(",") if s.strip()]
    except ValueError as exc:
        raise PosenetError(f"--samples must be comma-separated integers, got '{samples}'") from exc
    panels = {"poses.png": overlay_panel(data, split, list(ckpts), ids),
              "features.png": heatmap_panel(data, split, list(ckpts), ids)}  # fmt: skip
    for name, panel in panels.items():
        ok, png = cv2.imencode(".png", panel)
        click.echo(f"wrote {write_output(out / name, png.tobytes())}")


@main.command()
@click.argument("source", required=False)
@click.option(
    "--ckpt",
    "--pose",
    "ckpt",
    type=PATH,
    required=True,
    multiple=True,
    help="Pose checkpoint (last.pt of posenet train). Repeat it, one per object (posenet train --obj-id), to "
    "pose every object --detector finds (a detector of several objects; not with --box, --boxes, --onnx, "
    "--track, --filter or --batch).",
)
@click.option("--detector", type=PATH, default=None, help="Detector checkpoint (best.pt of train-detector).")
@click.option(
    "--camera",
    default=None,
    help="The camera that took SOURCE: fx,fy,cx,cy[,k1,k2,p1,p2,k3] (pixels, OpenCV distortion), a SPEED+ "
    "or BOP camera.json, a scgen preset name (default, speedplus, ...), or 'training' (the checkpoint's).",
)
@click.option(
    "--data", type=PATH, default=None, help="Predict a dataset split instead of SOURCE (its cameras)."
)
@click.option("--split", default="test", show_default=True, help="The split of --data.")
@click.option("--box", default=None, help="x,y,w,h: one box for every image, instead of the detector.")
@click.option(
    "--boxes",
    type=PATH,
    default=None,
    help="BOP detection JSON (posenet boxes): keyed by (scene_id, im_id) with --data, else (0, input index).",
)
@click.option(
    "--out", type=PATH, required=True, help="Folder for predictions.jsonl, overlays and --format files."
)
@click.option(
    "--format",
    "formats",
    multiple=True,
    type=click.Choice(PREDICT_FORMATS),
    help="Also write BOP19 results.csv or a SPEED+/Kelvins submission.csv (repeatable).",
)
@click.option("--no-vis", is_flag=True, help="No overlays (images, video, sheet.jpg).")
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True)
@click.option(
    "--onnx",
    "onnx_path",
    type=PATH,
    default=None,
    help="The pose network's ONNX graph (posenet export) run in onnxruntime instead of torch; a .onnx "
    "--detector runs there too.",
)
@click.option(
    "--min-score",
    type=FiniteFloatRange(0, 1),
    default=MIN_SCORE,
    show_default=True,
    help="The detector's score floor: a best box scoring less is no detection (flag no_detection).",
)
@passes_option(PREDICT_PASSES, "the default was chosen on held-out images (docs/benchmarks.md).")
@same_crop_option
@click.option(
    "--track",
    is_flag=True,
    help="Track on the navigation filter: each frame's crop seeded from the filter's predicted pose, its "
    "pose the filter's measurement; the detector runs to start and when the target is lost. Records gain "
    "the filtered and smoothed pose, velocity and angular velocity with their 1-sigma (needs --detector "
    "and the checkpoint's noise from posenet calibrate; a sequence dataset's frames go in time order).",
)
@click.option(
    "--filter",
    "filtered",
    is_flag=True,
    help="Run the navigation filter over every frame's pose, boxed as without it (the detector on every "
    "frame, or --box/--boxes): records gain the filtered and smoothed state; slower than --track, and its "
    "crops stay independent of the filter's estimate (docs/navigation.md).",
)
@click.option(
    "--dt",
    "frame_dt",
    type=FiniteFloatRange(min=0, min_open=True),
    default=None,
    help="With --track or --filter: seconds between frames of SOURCE (default: a video's frame interval; a "
    "sequence dataset's frames have their times).",
)
@filter_options
@click.option(
    "--batch",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="Frames predicted together: loaded and warped in threads, the detector (a .pt one; an .onnx "
    "one on the frames side by side) and the pose network run on the batch (posenet.predict.batch); "
    "1: one at a time. Not with --track.",
)
@click.option(
    "--cuda-graphs", is_flag=True, help="With --batch on CUDA: replay both networks as CUDA graphs."
)
@click.option("--bf16", is_flag=True, help="With --batch: run both networks under bf16 autocast.")
@click.option("--overwrite", is_flag=True, help="Write into an existing, non-empty --out.")
def predict(
    source: str | None,
    ckpt: tuple[Path, ...],
    detector: Path | None,
    camera: str | None,
    data: Path | None,
    split: str,
    box: str | None,
    boxes: Path | None,
    out: Path,
    formats: tuple[str, ...],
    no_vis: bool,
    device: str,
    onnx_path: Path | None,
    min_score: float,
    passes: int,
    same_crop_iou: float,
    track: bool,
    filtered: bool,
    frame_dt: float | None,
    accel_noise: float,
    angular_accel_noise: float,
    batch: int,
    cuda_graphs: bool,
    bf16: bool,
    overwrite: bool,
) -> None:
    """Poses from images a user brings: SOURCE is an image, a folder, a glob or a video (or --data DIR
    --split S). Each image is warped into the camera the network was trained with (lens, focal length and
    size: docs/posenet.md), boxed by --detector (or --box / --boxes; with --data and neither, the
    ground-truth boxes, as posenet eval), cropped, and its pose decoded in the user's camera."""
    from tqdm import tqdm

    from posenet.export.bench import resolve_device
    from posenet.predict.batch import BatchPredictor
    from posenet.predict.inputs import predict_inputs
    from posenet.predict.run import run_predict

    check_output(out, folder=True, overwrite=overwrite)
    if batch > 1 and (track or filtered):
        raise PosenetError("the navigation filter takes the frames one after another: --track and --filter "
                           "take no --batch")  # fmt: skip
    if track and filtered:
        raise PosenetError("--track runs the filter already (and seeds the crops from it): give one of "
                           "--track, --filter")  # fmt: skip
    if (cuda_graphs or bf16) and batch == 1:
        raise PosenetError("--cuda-graphs and --bf16 go with --batch N (N > 1)")
    if batch > 1 and len(ckpt) > 1:
        raise PosenetError(
            "several pose checkpoints (one per object) take the frames one at a time: no --batch"
        )
    nav_config = replace(NavConfig(), accel_noise=accel_noise, angular_accel_noise=angular_accel_noise)
    pose_ckpts = ckpt if len(ckpt) > 1 else ckpt[0]
    inputs = predict_inputs(source, pose_ckpts, detector, camera, data, split, box, boxes,
                            resolve_device(device), preset_intrinsics, onnx_path, min_score, passes, track,
                            frame_dt, nav_config, filtered, same_crop_iou)  # fmt: skip
    batched = None
    if batch > 1:
        batched = BatchPredictor(inputs.predictor, batch, detector, graphs=cuda_graphs, bf16=bf16)  # type: ignore[arg-type]
    make_output_folder(out)
    with tqdm(total=inputs.total, desc="predict", unit="img", dynamic_ncols=True) as bar:
        run = run_predict(inputs.predictor, inputs.frames, inputs.total, out, inputs.camera, inputs.box_for,
                          vis=not no_vis, formats=formats, video_fps=inputs.video_fps, progress=bar.update,
                          warn=tqdm.write, tracker=inputs.tracker, sequence_of=inputs.sequence_of,
                          batched=batched, frame_dt=inputs.frame_dt)  # fmt: skip
    if batched is not None:
        batched.close()
    posed = sum(r.get("R") is not None for r in run.records)
    images = len({r["index"] for r in run.records})  # several objects: a record per object
    click.echo(f"{images} inputs, {posed} poses, {run.failed} failed, "
               f"{images / max(run.seconds, 1e-9):.1f} images/s")  # fmt: skip
    if inputs.tracker is not None:
        filtered = [r["filter"] for r in run.records if r.get("filter") is not None]
        click.echo(f"tracking: the detector ran on {inputs.tracker.detections} of {len(run.records)} inputs; "
                   f"the filter posed {len(filtered)}, coasted on {sum(f['coasting'] for f in filtered)}, "
                   f"rejected a measurement's part on {sum(f['rejected'] for f in filtered)}")  # fmt: skip
    stages = inputs.predictor.timings.per_image_ms(images)
    click.echo("latency per image (ms): " + ", ".join(f"{k} {v:.1f}" for k, v in stages.items()))
    for path in run.files:
        click.echo(f"wrote {path}")
    if run.failed:
        raise PosenetError(f"{run.failed} of {images} inputs failed (see {run.files[0]})")


if __name__ == "__main__":  # `python -m posenet.cli`, e.g. under `torchrun -m`
    main()
