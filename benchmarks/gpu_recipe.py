"""GPU runbook: render a dataset, train the paper preset in bf16 within a time budget, evaluate, report.

On one GPU node (the defaults are sized for 16 cores and one GPU, 40 minutes in all):

    python benchmarks/gpu_recipe.py --out /scratch/recipe [--pretrained FILE]

The same chain on a CPU in a few minutes (CI runs it: tests/test_gpu_recipe.py):

    python benchmarks/gpu_recipe.py --tiny --out /tmp/recipe

The chain:
1. render --n samples with every core into OUT/data (Blender where bpy imports, else Mitsuba; a render
   already there is resumed);
2. train the config into OUT/run within --train-minutes (`posenet train --minutes`: the schedule is
   fitted while it runs, so that its cosine ends at the budget; posenet.training.budget);
3. evaluate the test split at ground-truth boxes (Patch-PnP): the summary, ADD@0.02 m per factor group
   (`scgen stats --sample-groups`) and the batch-1 latency of the network;
4. write OUT/report.md and OUT/report.json, and print the report.

The paper preset starts from timm's ImageNet weights, a download: on a node without a network pass
--pretrained FILE, a local classifier state dict (timm or torchvision keys) of the backbone.
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from harness import parser, run_script

from posenet import evaluate, train
from posenet.config import config_from_dict
from posenet.evaluation.evaluate import by_factor, by_factor_table, format_table, summary_rows
from posenet.export.bench import device_label
from posenet.models.backbone import initial_weights
from posenet.training.train import LAST, LOG_FILE
from scgen.dataset.stats import sample_groups
from scgen.io.atomic import atomic_write_text
from scgen.io.cores import usable_cores
from scgen.run.runner import RenderJob, run_render

CORES = usable_cores()


@dataclass(frozen=True)
class Recipe:
    """What one mode of the runbook renders, trains and evaluates."""

    n: int  # samples rendered
    resolution: tuple[int, int]
    quality: str
    config: dict[str, Any]  # the training config (a config file's content)
    train_minutes: float
    groups_n: int  # test images per factor group at most
    eval_workers: int


FULL = Recipe(
    n=3000,
    resolution=(640, 480),
    quality="draft",
    config={
        "preset": "paper",
        "data": {"workers": max(1, min(12, CORES - 2))},
        "optim": {"amp": "bf16", "ckpt_every": 10},
    },
    train_minutes=25.0,
    groups_n=500,
    eval_workers=max(0, min(8, CORES - 2)),
)
TINY = Recipe(
    n=24,
    resolution=(320, 240),
    quality="draft",
    config={
        "preset": "smoke",
        "model": {
            "input_res": 64,
            "output_res": 16,
            "head_channels": 32,
            "pnp_channels": 32,
            "fc_dims": [64, 32],
        },
        "data": {"workers": 0},
        "optim": {"amp": "bf16", "batch_size": 4, "warmup_iters": 10, "ckpt_every": 100},
    },
    train_minutes=0.25,
    groups_n=50,
    eval_workers=0,
)


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--out", type=Path, required=True, help="folder for data/, probe/, run/, report.*")
    ap.add_argument("--tiny", action="store_true", help="the CPU-sized chain (CI): 24 images, a 64 px crop")
    ap.add_argument("--n", type=int, help="samples to render (default: 3000; --tiny 24)")
    ap.add_argument("--train-minutes", type=float, help="training budget (default: 25; --tiny 0.25)")
    ap.add_argument("--variant", default="gdrnet", help="the paper row to train (default: gdrnet)")
    ap.add_argument("--pretrained", help="the backbone's initial weights: imagenet | package | FILE")
    ap.add_argument("--seed", type=int, default=0, help="dataset seed")
    return ap.parse_args()


def recipe_of(args: argparse.Namespace) -> Recipe:
    """The mode's recipe with the command line's overrides."""
    base = TINY if args.tiny else FULL
    config = {**base.config, "variant": args.variant}
    if args.pretrained is not None:
        config["model"] = {**config.get("model", {}), "pretrained": args.pretrained}
    return Recipe(
        n=args.n or base.n,
        resolution=base.resolution,
        quality=base.quality,
        config=config,
        train_minutes=args.train_minutes or base.train_minutes,
        groups_n=base.groups_n,
        eval_workers=base.eval_workers,
    )


def render(out: Path, recipe: Recipe, seed: int) -> dict[str, Any]:
    """The dataset, rendered with every core (resumed if there): what the report says of it."""
    try:
        import bpy  # noqa: F401

        backend = "blender"
    except ImportError:
        backend = "mitsuba"
    job = RenderJob(
        out=out, n=recipe.n, seed=seed, backend=backend, quality=recipe.quality,
        resolution=recipe.resolution, workers=CORES,
    )  # fmt: skip
    s = run_render(job, progress=True)
    return {
        "path": str(out), "n": recipe.n, "seed": seed, "backend": backend, "quality": recipe.quality,
        "resolution": "x".join(map(str, recipe.resolution)), "workers": CORES, "rendered": s["rendered"],
        "seconds": s["total_s"], "splits": s["splits"],
    }  # fmt: skip


def report_text(r: dict[str, Any], summary_table: str, factor_table: str) -> str:
    """The report as Markdown."""
    d, t, e = r["dataset"], r["training"], r["evaluation"]
    return "\n".join([
        f"# posenet GPU recipe ({'tiny, CPU chain' if r['tiny'] else 'full'})",
        "",
        f"- device: {r['device']}; {CORES} cores; torch {torch.__version__}",
        f"- dataset: {d['n']} samples, seed {d['seed']}, {d['resolution']}, {d['backend']}/{d['quality']}, "
        f"{d['workers']} workers: {d['rendered']} rendered in {d['seconds']:.0f} s; splits {d['splits']}",
        f"- training: {t['variant']}, preset {t['preset']}, precision {t['amp']}, batch {t['batch_size']}; "
        f"{t['steps']} steps fitted ({t['steps_run']} run), {1000 * t['step_s']:.0f} ms a step; "
        f"{t['seconds'] / 60:.1f} min for a {t['budget_minutes']:g} min budget; "
        f"final loss {t['final_loss']:.4f}",
        f"- evaluation: test split, ground-truth boxes, Patch-PnP; {e['seconds']:.0f} s",
        f"- batch-1 latency of the network: {e['latency_ms']:.2f} ms ({1000 / e['latency_ms']:.1f} FPS)",
        f"- wall time of the chain: {r['total_minutes']:.1f} min",
        "",
        "## Test split",
        "",
        "```",
        summary_table,
        "```",
        "",
        "## ADD@0.02 m by factor group (test split)",
        "",
        "```",
        factor_table,
        "```",
        "",
    ])  # fmt: skip


def run(args: argparse.Namespace) -> dict[str, Any]:
    tic = time.perf_counter()
    recipe = recipe_of(args)
    cfg = config_from_dict(recipe.config)  # checked before anything is rendered
    model_cfg = cfg.model_config()
    # the backbone's weights before the render: offline, without --pretrained FILE, it stops here in one line
    initial_weights(model_cfg.backbone, model_cfg.pretrained)
    args.out.mkdir(parents=True, exist_ok=True)
    data = args.out / "data"
    dataset = render(data, recipe, args.seed)

    run_dir = args.out / "run"
    shutil.rmtree(run_dir, ignore_errors=True)
    t_train = time.perf_counter()
    ckpt = train(data, run_dir, cfg, minutes=recipe.train_minutes)
    train_s = time.perf_counter() - t_train
    final = json.loads((run_dir / LOG_FILE).read_text().splitlines()[-1])
    state = torch.load(ckpt, weights_only=True)

    t_eval = time.perf_counter()
    result = evaluate(data, ckpt, "test", workers=recipe.eval_workers)
    groups = sample_groups(data, "test", recipe.groups_n, args.seed)
    groups_file = args.out / f"groups_test_n{recipe.groups_n}_s{args.seed}.json"
    atomic_write_text(groups_file, json.dumps(groups, indent=1) + "\n")
    factors = by_factor(data, [ckpt], groups_file, "test", workers=recipe.eval_workers)
    eval_s = time.perf_counter() - t_eval

    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    report = {
        "tiny": args.tiny,
        "device": device_label(device),
        "dataset": dataset,
        "training": {
            "variant": cfg.variant, "preset": cfg.preset, "amp": state["amp"],
            "batch_size": cfg.optim.batch_size, "steps": state["schedule_steps"], "steps_run": final["step"],
            "step_s": train_s / final["step"],
            "seconds": train_s, "budget_minutes": recipe.train_minutes,
            "final_loss": final["loss"], "checkpoint": str(ckpt),
        },
        "evaluation": {
            "seconds": eval_s, "latency_ms": result.summary["latency_ms"], "summary": result.summary,
            "by_factor": factors,
        },
    }  # fmt: skip
    report["total_minutes"] = (time.perf_counter() - tic) / 60
    summary_table = format_table([f"{cfg.variant} on test", "value"], summary_rows([result.summary]))
    text = report_text(report, summary_table, by_factor_table(factors))
    atomic_write_text(args.out / "report.md", text)
    atomic_write_text(args.out / "report.json", json.dumps(report, indent=1) + "\n")
    print(text)
    print(f"wrote {args.out / 'report.md'} and report.json; checkpoint {run_dir / LAST}")
    return report


if __name__ == "__main__":
    run_script(run, parse_args())
