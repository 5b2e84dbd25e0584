"""posenet learning benchmark: train a config on an scgen dataset, following the held-out test split.

Reproduce the figures of docs/benchmarks.md (renders 1000 samples with Mitsuba at 320x240, seed 7, into
OUT/data, then trains the `smoke` config for its whole schedule into OUT/run-gdrnet; measured on 2 idle
cores: about 6 min of rendering, 25-45 min of training, the machine's speed drifting, and 2 min of
evaluation):

    python benchmarks/posenet_learning.py --out /tmp/learn

GDR-Net against GAP-GDRNet on the same set (issue 20 item 4; each variant trains in turn, into
OUT/run-VARIANT):

    python benchmarks/posenet_learning.py --out /tmp/learn --variant gdrnet --variant gap-gdrnet

Training runs in chunks: train(max_steps=k) up to each evaluation step k, then (resume=True) on to the
next; the training code guarantees that the resumed run equals an uninterrupted one. After each chunk
the checkpoint is evaluated on the test split (scene-factor combinations never seen in training) with
posenet.evaluate.evaluate, which gives the learning curve. With --steps shorter than the config's
schedule the learning-rate schedule is still the config's (warmup + flat + cosine over all its
epochs): the run stops part-way through it, before (or during) the cosine decay.

Prints, per variant: the curve (one line per evaluation), the final checkpoint's rotation error (mean,
median), share of turned poses, translation error, ADD@0.02 m, ADD@0.1d split into its two causes (the
ADD@0.1d of the predicted rotation at the GT translation and of the predicted translation at the GT
rotation), the median depth error as a share of the depth, and instance counts on the train and test
splits, the floors of issue 20, and the training wall time and samples/s. Then ADD@0.02 m per
factor group of the test split, one column per variant (the groups `scgen stats --sample-groups` draws,
evaluated by posenet.evaluate.by_factor, the layout of `posenet eval --by-factor` and of the paper's
Table 5). Writes OUT/learning_curve-VARIANT.png (loss terms; test recalls and rotation error against
steps) and OUT/learning.json (every figure printed, plus the curve points).

Re-running with the same --out reuses (resumes) the rendered dataset in OUT/data; an OUT/run-VARIANT that
holds a run already is refused (pass --overwrite to delete it first).
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from posenet.config import TrainConfig, load_config
from posenet.data import open_split
from posenet.errors import PosenetError
from posenet.evaluate import by_factor, evaluate, format_table, summary_rows
from posenet.losses import LOSS_TERMS
from posenet.train import LAST, LOG_FILE, steps_per_epoch, train
from scgen.dataset.stats import sample_groups
from scgen.errors import ScgenError
from scgen.io.atomic import atomic_write_text
from scgen.run.runner import RenderJob, run_render

CURVE_POINTS = 8  # default number of evaluations over the run
# the benchmark's dataset (each a --flag's default): 1000 samples of seed 7 at 320x240, Mitsuba, 2 workers
RENDER_N, SEED, RESOLUTION, BACKEND, WORKERS = 1000, 7, (320, 240), "mitsuba", 2
# issue 20's floors for the CPU recipe: (split, figure, bound, "max" | "min")
FLOORS = (
    ("test", "re_deg_median", 20.0, "max"),
    ("test", "add_0.1d", 0.20, "min"),
    ("train", "re_deg_median", 10.0, "max"),
)
# the summary figures of the final table, train and test side by side
LEARNING_FIGURES = ("n", "re_deg", "re_deg_median", "turned", "te_m", "te_m_median", "tz_rel_median",
                    "add_0.02m", "add_0.1d", "add_rot_0.1d", "te_0.1d")  # fmt: skip


def parse_resolution(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"resolution must look like 320x240, got {text!r}") from None
    return w, h


def positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def parse_args() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
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


def schedule(data: Path, cfg: TrainConfig) -> tuple[int, int, int]:
    """(training instances, steps per epoch, total steps) exactly as posenet.train computes them."""
    o = cfg.optim
    ds = open_split(data, "train", cfg.data, cfg.model_config(), train=True, seed=o.seed)
    per_epoch = steps_per_epoch(len(ds), o)
    return len(ds), per_epoch, o.epochs * per_epoch


Floor = tuple[str, str, float, str]  # (split, figure, bound, "max" | "min")


def floor_rows(final: dict[str, dict[str, Any]], floors: tuple[Floor, ...] = FLOORS) -> list[dict[str, Any]]:
    """Each floor with the split's figure in `final` and whether it is met."""
    rows = []
    for split, key, bound, kind in floors:
        value = final[split][key]
        met = bool(value <= bound if kind == "max" else value >= bound)
        rows.append({"split": split, "figure": key, "bound": bound, "kind": kind, "value": value, "met": met})
    return rows


def floor_lines(final: dict[str, dict[str, Any]], floors: tuple[Floor, ...] = FLOORS) -> list[str]:
    """One line per floor: the figure, the bound and whether it is met."""
    lines = []
    for r in floor_rows(final, floors):
        sign = "<=" if r["kind"] == "max" else ">="
        lines.append(f"{r['split']} {r['figure']} {r['value']:.3f} ({sign} {r['bound']}): "
                     f"{'met' if r['met'] else 'NOT met'}")  # fmt: skip
    return lines


def moving_average(values: np.ndarray, window: int) -> np.ndarray:
    """Trailing mean over `window` values (fewer at the start)."""
    c = np.cumsum(np.insert(values, 0, 0.0))
    idx = np.arange(1, len(values) + 1)
    lo = np.maximum(idx - window, 0)
    return (c[idx] - c[lo]) / (idx - lo)


def plot(path: Path, log_rows: list[dict[str, Any]], curve: list[dict[str, Any]], title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, (ax_l, ax_r) = plt.subplots(1, 2, figsize=(13, 5.5))
    steps = np.array([r["step"] for r in log_rows])
    window = int(np.clip(len(log_rows) // 25, 1, 100))
    for key in ("loss", *LOSS_TERMS):
        v = moving_average(np.array([r[key] for r in log_rows], dtype=float), window)
        v = np.where(v > 0, v, np.nan)  # log axis
        label = "total (weighted sum)" if key == "loss" else key
        ax_l.plot(
            steps, v, label=label, lw=2.2 if key == "loss" else 1.2, color="k" if key == "loss" else None
        )
    ax_l.set_yscale("log")
    ax_l.set_xlabel("training step")
    ax_l.set_ylabel("loss per batch (log scale; terms unweighted)")
    ax_l.set_title(f"Training loss (moving average over {window} step{'s' * (window > 1)})")
    ax_l.grid(True, which="both", alpha=0.3)
    ax_l.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax_l.legend(fontsize=8, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.13))

    x = [p["step"] for p in curve]
    ax_r.plot(x, [100 * p["add_0.1d"] for p in curve], "o-", color="tab:blue", label="ADD@0.1d (%)")
    ax_r.plot(x, [100 * p["add_0.02m"] for p in curve], "s-", color="tab:green", label="ADD@0.02 m (%)")
    ax_r.set_ylim(-2, 102)
    ax_r.set_xlabel("training step")
    ax_r.set_ylabel("recall on the test split (%)")
    ax_r.grid(True, alpha=0.3)
    ax_r.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax2 = ax_r.twinx()
    ax2.plot(x, [p["re_deg_median"] for p in curve], "^--", color="tab:red", label="rotation error, median")
    ax2.plot(x, [p["re_deg"] for p in curve], "v:", color="tab:orange", label="rotation error, mean")
    ax2.set_ylabel("rotation error (deg)", color="tab:red")
    ax2.tick_params(axis="y", colors="tab:red")
    errs = [p[k] for p in curve for k in ("re_deg", "re_deg_median") if math.isfinite(p[k])]
    ax2.set_ylim(0, 1.1 * max([*errs, 1.0]))
    n = curve[-1]["n"] if curve else 0
    ax_r.set_title(f"Held-out test split ({n} instances)")
    h1, l1 = ax_r.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax_r.legend(h1 + h2, l1 + l2, fontsize=8, ncol=2, loc="upper center", bbox_to_anchor=(0.5, -0.13))
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def pct(v: float | None) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{100 * v:.2f}"


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


def run_folder(out: Path, cfg: TrainConfig) -> Path:
    """OUT/run-VARIANT: where the benchmark trains that variant."""
    return out / f"run-{cfg.variant}"


def clear_run_folders(args: argparse.Namespace, cfgs: list[TrainConfig]) -> None:
    """Refuse (or with --overwrite delete) every variant's run folder that holds a run, before any
    training, so that a second variant never fails after the first has trained."""
    for cfg in cfgs:
        run_dir = run_folder(args.out, cfg)
        if (run_dir / LAST).exists():
            if not args.overwrite:
                raise PosenetError(f"{run_dir} already holds a run; pass --overwrite or choose another --out")
            shutil.rmtree(run_dir)


def train_and_follow(args: argparse.Namespace, data: Path, cfg: TrainConfig) -> dict[str, Any]:
    """Train one variant into OUT/run-VARIANT in chunks, evaluating the test split after each; then the
    final checkpoint on the train split. Prints the curve, the final table and the floors; writes the
    variant's learning-curve PNG. Returns everything learning.json records of the run."""
    run_dir = run_folder(args.out, cfg)
    n_train, per_epoch, total = schedule(data, cfg)
    o = cfg.optim
    steps = total if args.steps is None else args.steps
    if steps > total:
        print(f"notice: --steps {steps} exceeds the config's schedule ({total} steps); capped at {total}")
        steps = total
    every = args.eval_every or max(1, math.ceil(steps / CURVE_POINTS))
    points = [*range(every, steps, every), steps]
    print(
        f"\ntraining: {cfg.variant} ({args.config} config), {n_train} training instances, batch "
        f"{o.batch_size}, {per_epoch} steps/epoch; {steps} of the schedule's {total} steps "
        f"({o.epochs} epochs), test evaluation at steps {', '.join(map(str, points))}"
    )
    if steps < total:
        print(
            f"note: the lr schedule is the config's {total}-step schedule (warmup {o.warmup_iters} steps, "
            f"cosine decay from step {math.ceil(o.anneal_point * total)}); this run stops at step {steps}"
        )

    curve: list[dict[str, Any]] = []
    train_s = eval_s = 0.0
    ckpt = run_dir / LAST
    final_test = None
    for k in points:
        tic = time.perf_counter()
        ckpt = train(data, run_dir, cfg, resume=k > points[0], max_steps=k)
        train_s += time.perf_counter() - tic
        tic = time.perf_counter()
        final_test = evaluate(data, ckpt, "test", workers=args.eval_workers)
        eval_s += time.perf_counter() - tic
        s = final_test.summary
        curve.append({"step": k, "epoch": k / per_epoch, "train_s": train_s, **s})
        print(
            f"step {k:>6}/{steps} (epoch {k / per_epoch:6.2f}): test ADD@0.1d {pct(s['add_0.1d']):>6} %, "
            f"ADD@0.02m {pct(s['add_0.02m']):>6} %, rotation error {s['re_deg']:7.2f} deg mean / "
            f"{s['re_deg_median']:7.2f} median, translation error {s['te_m']:.4f} m",
            flush=True,
        )

    assert final_test is not None  # points is never empty
    tic = time.perf_counter()
    final = {"train": evaluate(data, ckpt, "train", workers=args.eval_workers).summary}
    final["test"] = final_test.summary  # the last curve point: the final checkpoint
    eval_s += time.perf_counter() - tic

    rows_log = [json.loads(ln) for ln in (run_dir / LOG_FILE).read_text().splitlines()]
    step_s = statistics.median(r["step_s"] for r in rows_log)
    samples = steps * o.batch_size

    print(f"\nfinal checkpoint ({ckpt}, step {steps}):")
    tr, te = final["train"], final["test"]
    print(format_table([final_test.variant, "train", "test"], summary_rows([tr, te], LEARNING_FIGURES)))
    print("floors (issue 20): " + "; ".join(floor_lines(final)))
    kept = "" if cfg.data.min_visib_fract == 0 else f" with visible fraction > {cfg.data.min_visib_fract}"
    print(f"(instances: every one with a visible pixel; training used {n_train} train instances{kept})")
    print(
        f"training: {steps} steps x batch {o.batch_size} = {samples} samples in {train_s:.1f} s wall "
        f"({samples / train_s:.1f} samples/s, including {len(points) - 1} restart(s) for evaluation); "
        f"median step {1000 * step_s:.0f} ms ({o.batch_size / step_s:.1f} samples/s)"
    )
    print(f"evaluation: {eval_s:.1f} s ({len(points)} test evaluations and the train split)")

    title = (
        f"{final_test.variant} ({args.config} config) on {data.name}: {n_train} training instances, "
        f"batch {o.batch_size}, {steps}" + (f" of {total}" if steps < total else "") + " steps"
    )
    png = args.out / f"learning_curve-{cfg.variant}.png"
    plot(png, rows_log, curve, title)
    print(f"wrote {png}")
    return {
        "run": str(run_dir),
        "ckpt": str(ckpt),
        "config": cfg.to_dict(),
        "variant": final_test.variant,
        "train_instances": n_train,
        "steps_per_epoch": per_epoch,
        "schedule_steps": total,
        "steps": steps,
        "eval_every": every,
        "curve": curve,
        "final": final,
        "timing": {
            "train_wall_s": train_s,
            "train_samples_per_s": samples / train_s,
            "median_step_s": step_s,
            "median_step_samples_per_s": o.batch_size / step_s,
            "eval_s": eval_s,
        },
    }


def run(args: argparse.Namespace) -> None:
    args.out.mkdir(parents=True, exist_ok=True)
    cfgs = variant_configs(args)  # every --variant checked before anything is rendered or trained
    clear_run_folders(args, cfgs)
    data = get_dataset(args)
    runs = [train_and_follow(args, data, cfg) for cfg in cfgs]

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


def run_script(run: Callable[[argparse.Namespace], object], args: argparse.Namespace) -> None:
    """Run a benchmark: bad input (PosenetError, ScgenError) ends it with one line and exit status 1."""
    try:
        run(args)
    except (PosenetError, ScgenError) as exc:
        sys.exit(f"error: {exc}")


def main() -> None:
    run_script(run, parse_args())


if __name__ == "__main__":
    main()
