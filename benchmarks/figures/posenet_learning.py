"""posenet learning benchmark: train a config on an scgen dataset, following the held-out test split.

Reproduce the figures of docs/benchmarks.md (renders 1000 samples with Mitsuba at 320x240, seed 7, into
OUT/data, then trains the `smoke` config for its whole schedule into OUT/run-gdrnet; measured on 2 idle
cores: about 6 min of rendering, 25-45 min of training, the machine's speed drifting, and 2 min of
evaluation):

    python benchmarks/figures/posenet_learning.py --out /tmp/learn

GDR-Net against GAP-GDRNet on the same set (issue 20 item 4; each variant trains in turn, into
OUT/run-VARIANT):

    python benchmarks/figures/posenet_learning.py --out /tmp/learn --variant gdrnet --variant gap-gdrnet

Training runs in chunks: train(max_steps=k) up to each evaluation step k, then (resume=True) on to the
next; the training code guarantees that the resumed run equals an uninterrupted one. After each chunk
the checkpoint is evaluated on the test split (scene-factor combinations never seen in training) with
posenet.evaluate, which gives the learning curve. With --steps shorter than the config's schedule the
learning-rate schedule is still the config's (warmup + flat + cosine over all its epochs): the run stops
part-way through it, before (or during) the cosine decay.

Prints, per variant: the curve (one line per evaluation), the final checkpoint's rotation error (mean,
median), share of turned poses, translation error, ADD@0.02 m, ADD@0.1d split into its two causes (the
ADD@0.1d of the predicted rotation at the GT translation and of the predicted translation at the GT
rotation), the median depth error as a share of the depth, and instance counts on the train and test
splits, the floors of issue 20, and the training wall time and samples/s. Then ADD@0.02 m per
factor group of the test split, one column per variant (the groups `scgen stats --sample-groups` draws,
evaluated by posenet.evaluation.evaluate.by_factor, the layout of `posenet eval --by-factor` and of the
paper's Table 5). Writes OUT/learning_curve-VARIANT.png (loss terms; test recalls and rotation error against
steps) and OUT/learning.json (every figure printed, plus the curve points).

Re-running with the same --out reuses (resumes) the rendered dataset in OUT/data; an OUT/run-VARIANT that
holds a run already is refused (pass --overwrite to delete it first).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import (
    BACKEND,
    RENDER_N,
    RESOLUTION,
    SEED,
    WORKERS,
    fresh_run,
    parse_resolution,
    parser,
    pct,
    positive,
    run_script,
)
from harness.pose import CURVE_POINTS, run_folder, train_and_follow

from posenet.config import TrainConfig, load_config
from posenet.errors import PosenetError
from posenet.evaluation.evaluate import by_factor, format_table
from scgen.dataset.stats import sample_groups
from scgen.io.atomic import atomic_write_text
from scgen.run.runner import RenderJob, run_render

# issue 20's floors for the CPU recipe: (split, figure, bound, "max" | "min")
FLOORS = (
    ("test", "re_deg_median", 20.0, "max"),
    ("test", "add_0.1d", 0.20, "min"),
    ("train", "re_deg_median", 10.0, "max"),
)


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument(
        "--out",
        type=Path,
        required=True,
        help="Output folder: data/ (if rendered), run-VARIANT/, PNGs and JSON.",
    )
    ap.add_argument(
        "--data", type=Path, default=None, help="Existing scgen dataset (default: render one into OUT/data)."
    )
    render = ap.add_argument_group("rendering (only without --data)")
    render.add_argument(
        "--render-n", type=positive, default=RENDER_N, help="Samples to render [%(default)s]."
    )
    render.add_argument("--seed", type=int, default=SEED, help="Dataset seed [%(default)s].")
    render.add_argument(
        "--resolution", type=parse_resolution, default=RESOLUTION, help="Image size WxH [320x240]."
    )
    render.add_argument("--backend", default=BACKEND, help="scgen backend: mitsuba | blender [%(default)s].")
    render.add_argument(
        "--quality", default="default", help="scgen quality: draft | default | high [default]."
    )
    render.add_argument(
        "--workers", type=positive, default=WORKERS, help="Render worker processes [%(default)s]."
    )
    train_g = ap.add_argument_group("training")
    train_g.add_argument("--config", default="smoke", help="paper | smoke | a YAML/TOML config file [smoke].")
    train_g.add_argument(
        "--variant",
        action="append",
        default=None,
        help="Variant to train instead of the config's; repeat it to train several on the same set and "
        "compare them (--variant gdrnet --variant gap-gdrnet).",
    )
    train_g.add_argument(
        "--epochs", type=positive, default=None, help="Override optim.epochs (this sets the lr schedule)."
    )
    train_g.add_argument(
        "--steps",
        type=positive,
        default=None,
        help="Stop after N steps [and at most: the config's schedule]; the lr schedule stays the config's.",
    )
    train_g.add_argument(
        "--loader-workers", type=int, default=None, help="Override data.workers (training loader processes)."
    )
    train_g.add_argument("--overwrite", action="store_true", help="Delete an existing OUT/run first.")
    ev = ap.add_argument_group("evaluation")
    ev.add_argument(
        "--eval-every",
        type=positive,
        default=None,
        help=f"Evaluate the test split every K steps [about {CURVE_POINTS} points over the run].",
    )
    ev.add_argument(
        "--eval-workers", type=int, default=0, help="Loader processes of each evaluation [0: in process]."
    )
    ev.add_argument(
        "--groups-n", type=positive, default=500, help="Test samples per factor group (scgen stats) [500]."
    )
    ev.add_argument("--groups-seed", type=int, default=0, help="Seed of the factor-group draw [0].")
    return ap.parse_args()


def get_dataset(args: argparse.Namespace) -> Path:
    """The --data folder, or OUT/data rendered (resumed when a render is already there)."""
    if args.data is not None:
        if not args.data.is_dir():
            raise PosenetError(f"--data {args.data} is not a folder")
        return args.data
    data = args.out / "data"
    job = RenderJob(
        out=data, n=args.render_n, seed=args.seed, backend=args.backend, quality=args.quality,
        resolution=args.resolution, workers=args.workers,
    )  # fmt: skip
    print(
        f"dataset: {data} ({args.render_n} samples, seed {args.seed}, {args.resolution[0]}x"
        f"{args.resolution[1]}, {args.backend}/{args.quality}, {args.workers} workers; resumes if present)"
    )
    s = run_render(job, progress=True)
    splits = ", ".join(f"{k} {v}" for k, v in s["splits"].items())
    print(f"dataset: rendered {s['rendered']}, reused {s['skipped']}, {s['total_s']:.0f} s; {splits}")
    return data


def variant_configs(args: argparse.Namespace) -> list[TrainConfig]:
    """One TrainConfig per --variant (the config's own variant when none is named), each validated."""
    cfgs = [load_config(args.config, variant=v, epochs=args.epochs) for v in (args.variant or [None])]
    names = [c.variant for c in cfgs]
    if len(set(names)) < len(names):
        raise PosenetError(f"--variant names a variant twice: {', '.join(names)}")
    if args.loader_workers is not None:
        if args.loader_workers < 0:
            raise PosenetError("--loader-workers must be >= 0")
        for c in cfgs:
            c.data.workers = args.loader_workers
    return cfgs


def run(args: argparse.Namespace) -> None:
    args.out.mkdir(parents=True, exist_ok=True)
    cfgs = variant_configs(args)  # every --variant checked before anything is rendered or trained
    for cfg in cfgs:  # before any training, so that a second variant never fails after the first has trained
        fresh_run(run_folder(args.out, cfg), args.overwrite)
    data = get_dataset(args)
    runs = [
        train_and_follow(
            data, args.out, cfg, args.config, FLOORS, args.steps, args.eval_every, args.eval_workers
        )
        for cfg in cfgs
    ]

    groups = sample_groups(data, "test", args.groups_n, args.groups_seed)
    groups_file = args.out / f"groups_test_n{args.groups_n}_s{args.groups_seed}.json"
    atomic_write_text(groups_file, json.dumps(groups, indent=1) + "\n")
    tic = time.perf_counter()
    factors = by_factor(data, [Path(r["ckpt"]) for r in runs], groups_file, "test", workers=args.eval_workers)
    cols = factors["columns"]
    print(
        f"\ntest split by factor group ({args.groups_n} per group at most, seed {args.groups_seed}; "
        f"{time.perf_counter() - tic:.0f} s), one column per variant:"
    )
    print(
        format_table(
            ["ADD@0.02m (%)", "n", *cols],
            [
                [f"{f}/{g}", str(factors["n"][f][g]), *(pct(vals[c]) for c in cols)]
                for f, gs in factors["groups"].items()
                for g, vals in gs.items()
            ],
        )
    )
    result = {"data": str(data), "runs": runs, "by_factor": factors, "groups_file": str(groups_file)}
    atomic_write_text(args.out / "learning.json", json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out / 'learning.json'}")


if __name__ == "__main__":
    run_script(run, parse_args())
