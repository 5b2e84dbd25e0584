"""posenet training runs that several benchmarks share: the recipe's schedule, floors, a run followed
on the test split (the learning benchmark's, which the control runs too), the corridor control's data set,
the ablation's runs (which the range benchmark repeats on wider attitude ranges), a random rotation's
error, and the training loader's throughput.

Resuming: `resumed_json` keeps a finished step's result; `train` resumes a run from its last.pt.
"""

from __future__ import annotations

import json
import math
import os
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy.optimize import brentq
from torch.utils.data import DataLoader

from harness import BACKEND, SEED, WORKERS, pct, pyplot
from posenet import evaluate, train
from posenet.config import TrainConfig, load_config
from posenet.data import PoseDataset, open_split
from posenet.data.layout import scan_split
from posenet.data.object_model import load_object_model
from posenet.evaluation.evaluate import format_table, summary_rows
from posenet.evaluation.metrics import add_error, depth_error_rel, rotation_error_deg
from posenet.training.losses import LOSS_TERMS
from posenet.training.train import LAST, LOG_FILE, steps_per_epoch, worker_init
from scgen.dataset.layout import Layout
from scgen.io.atomic import atomic_write_text
from scgen.run.runner import RenderJob, run_render
from scgen.scenes.attitude import nominal_rotation, ray_rotation

CURVE_POINTS = 8  # default number of evaluations over a followed run
# the summary figures of a followed run's final table, train and test side by side
LEARNING_FIGURES = ("n", "re_deg", "re_deg_median", "turned", "te_m", "te_m_median", "tz_rel_median",
                    "add_0.02m", "add_0.1d", "add_rot_0.1d", "te_0.1d")  # fmt: skip
# the corridor control's data set (benchmarks/figures/posenet_control.py): 2400 samples at 320x240 whose
# target holds its attitude within a 20 deg cone (+-20 deg of roll) and is close
CONTROL_N, CONTROL_RESOLUTION = 2400, (320, 240)
CONTROL_SCENE = {
    "pose": {"distribution": "cone", "max_angle_deg": 20.0, "roll_deg": [-20.0, 20.0]},
    "distance": {"min_px": 240.0, "max_px": 360.0},
}
ABLATION_STEPS = 1260  # the ablation's runs: 6 epochs of the control's 1,680 training images at batch 8
# the median rotation error of a guess uniform over SO(3): the angle's CDF is (t - sin t) / pi
CHANCE_RE_DEG = float(np.rad2deg(brentq(lambda t: t - np.sin(t) - np.pi / 2, 0.0, np.pi)))
Floor = tuple[str, str, float, str]  # (split, figure, bound, "max" | "min")


def schedule(data: Path, cfg: TrainConfig) -> tuple[int, int, int]:
    """(training instances, steps per epoch, total steps) exactly as posenet.training.train computes them."""
    o = cfg.optim
    ds = open_split(data, "train", cfg.data, cfg.model_config(), train=True, seed=o.seed)
    per_epoch = steps_per_epoch(len(ds), o)
    return len(ds), per_epoch, o.epochs * per_epoch


def floor_rows(final: dict[str, dict[str, Any]], floors: tuple[Floor, ...]) -> list[dict[str, Any]]:
    """Each floor with the split's figure in `final` and whether it is met."""
    rows = []
    for split, key, bound, kind in floors:
        value = final[split][key]
        met = bool(value <= bound if kind == "max" else value >= bound)
        rows.append({"split": split, "figure": key, "bound": bound, "kind": kind, "value": value, "met": met})
    return rows


def floor_lines(final: dict[str, dict[str, Any]], floors: tuple[Floor, ...]) -> list[str]:
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
    """The learning curve: the loss terms against steps (left), the test split's recalls and rotation
    errors at each evaluation (right)."""
    from matplotlib.ticker import MaxNLocator

    plt = pyplot()

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


def resumed_json(path: Path, compute: Callable[[], dict[str, Any]]) -> dict[str, Any]:
    """Resume: the result at `path` when a run before this one wrote it, else `compute()`'s, written there
    atomically (so an interrupted step leaves no result behind)."""
    if path.exists():
        return json.loads(path.read_text())
    result = compute()
    atomic_write_text(path, json.dumps(result, indent=1) + "\n")
    return result


def paper_dataset(data: Path) -> PoseDataset:
    """The train split as the paper preset loads it (its augmentations, 256/64): what the loader
    benchmarks time."""
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


def run_folder(out: Path, cfg: TrainConfig) -> Path:
    """OUT/run-VARIANT: where a followed run trains that variant."""
    return out / f"run-{cfg.variant}"


def train_and_follow(
    data: Path,
    out: Path,
    cfg: TrainConfig,
    config_name: str,
    floors: tuple[Floor, ...],
    steps: int | None = None,
    eval_every: int | None = None,
    eval_workers: int = 0,
) -> dict[str, Any]:
    """Train one variant into OUT/run-VARIANT in chunks, evaluating the test split after each (every
    `eval_every` steps, or CURVE_POINTS times), to `steps` steps (the config's schedule, which the lr
    follows in any case); then the final checkpoint on the train split. Prints the curve, the final table
    and the `floors`; writes OUT/learning_curve-VARIANT.png. Returns everything learning.json records of
    the run."""
    run_dir = run_folder(out, cfg)
    n_train, per_epoch, total = schedule(data, cfg)
    o = cfg.optim
    steps = total if steps is None else steps
    if steps > total:
        print(f"notice: --steps {steps} exceeds the config's schedule ({total} steps); capped at {total}")
        steps = total
    every = eval_every or max(1, math.ceil(steps / CURVE_POINTS))
    points = [*range(every, steps, every), steps]
    print(
        f"\ntraining: {cfg.variant} ({config_name} config), {n_train} training instances, batch "
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
        final_test = evaluate(data, ckpt, "test", workers=eval_workers)
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
    final = {"train": evaluate(data, ckpt, "train", workers=eval_workers).summary}
    final["test"] = final_test.summary  # the last curve point: the final checkpoint
    eval_s += time.perf_counter() - tic

    rows_log = [json.loads(ln) for ln in (run_dir / LOG_FILE).read_text().splitlines()]
    step_s = statistics.median(r["step_s"] for r in rows_log)
    samples = steps * o.batch_size

    print(f"\nfinal checkpoint ({ckpt}, step {steps}):")
    tr, te = final["train"], final["test"]
    print(format_table([final_test.variant, "train", "test"], summary_rows([tr, te], LEARNING_FIGURES)))
    print("floors: " + "; ".join(floor_lines(final, floors)))
    kept = "" if cfg.data.min_visib_fract == 0 else f" with visible fraction > {cfg.data.min_visib_fract}"
    print(f"(instances: every one with a visible pixel; training used {n_train} train instances{kept})")
    print(
        f"training: {steps} steps x batch {o.batch_size} = {samples} samples in {train_s:.1f} s wall "
        f"({samples / train_s:.1f} samples/s, including {len(points) - 1} restart(s) for evaluation); "
        f"median step {1000 * step_s:.0f} ms ({o.batch_size / step_s:.1f} samples/s)"
    )
    print(f"evaluation: {eval_s:.1f} s ({len(points)} test evaluations and the train split)")

    title = (
        f"{final_test.variant} ({config_name} config) on {data.name}: {n_train} training instances, "
        f"batch {o.batch_size}, {steps}" + (f" of {total}" if steps < total else "") + " steps"
    )
    png = out / f"learning_curve-{cfg.variant}.png"
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


def render_control(
    out: Path, n: int = CONTROL_N, seed: int = SEED, scene: dict[str, Any] = CONTROL_SCENE,
    model: str | None = None,
) -> Path:  # fmt: skip
    """The control set (or `scene`'s variant of it, of bundled model or mesh `model`: None, the default
    spacecraft) in OUT/data, resumed when a render is there."""
    data = out / "data"
    job = RenderJob(out=data, n=n, seed=seed, backend=BACKEND, resolution=CONTROL_RESOLUTION, workers=WORKERS,
                    overrides=scene, model_path=None if model is None else Path(model))  # fmt: skip
    s = run_render(job, progress=True)
    print(f"dataset: {data}, rendered {s['rendered']}, reused {s['skipped']}, {s['total_s']:.0f} s; "
          + ", ".join(f"{k} {v}" for k, v in s["splits"].items()))  # fmt: skip
    return data


def prior(data: Path, obj_id: int = 1) -> dict[str, float]:
    """What knowing the corridor alone scores on the test split: the nominal attitude at the true
    translation (rotation error, ADD@0.1d of the rotation) and the train split's median depth along the
    true ray (ADD@0.1d of the translation, median depth error)."""
    R0 = nominal_rotation(json.loads(Layout(data).config_path.read_text())["pose"])
    train_z = float(np.median([i.t[2] for i in scan_split(data, "train", obj_id)]))
    test = [i for i in scan_split(data, "test", obj_id) if i.px_count_visib > 0]
    R_gt, t_gt = (torch.from_numpy(np.stack([getattr(i, k) for i in test])) for k in ("R", "t"))
    R_pred = torch.from_numpy(np.stack([ray_rotation(i.t) @ R0 for i in test]))
    t_pred = t_gt * (train_z / t_gt[:, 2:])
    obj = load_object_model(data, obj_id, 1, 1000)
    points, threshold = torch.from_numpy(obj.pm_points), 0.1 * obj.diameter
    # medians as posenet eval takes them (the mean of the middle two; torch's median takes the lower)
    return {"re_deg_median": float(np.median(rotation_error_deg(R_pred, R_gt).numpy())),
            "add_rot_0.1d": float((add_error(R_pred, t_gt, R_gt, t_gt, points) < threshold).double().mean()),
            "te_0.1d": float((add_error(R_gt, t_pred, R_gt, t_gt, points) < threshold).double().mean()),
            "tz_rel_median": float(np.median(depth_error_rel(t_pred, t_gt).numpy()))}  # fmt: skip


def run_config(variant: str, seed: int, steps: int, data: Path) -> TrainConfig:
    """The CPU recipe for `variant` with training seed `seed`, its schedule fitted to `steps` steps."""
    cfg = load_config("smoke", variant=variant)
    cfg.optim.seed = seed
    cfg.optim.epochs = max(1, math.ceil(steps / schedule(data, cfg)[1]))
    return cfg


def train_one(data: Path, run_dir: Path, cfg: TrainConfig, steps: int, eval_workers: int) -> dict[str, Any]:
    """Train (or resume) one run to `steps` steps and evaluate it on the test split, recording its wall
    time and the machine's load; kept in RUN/result.json, which a rerun reads back."""
    return resumed_json(run_dir / "result.json", lambda: _train_one(data, run_dir, cfg, steps, eval_workers))


def _train_one(data: Path, run_dir: Path, cfg: TrainConfig, steps: int, eval_workers: int) -> dict[str, Any]:
    load_before = os.getloadavg()
    tic = time.perf_counter()
    ckpt = train(data, run_dir, cfg, resume=(run_dir / LAST).exists(), max_steps=steps)
    wall = time.perf_counter() - tic
    test = evaluate(data, ckpt, "test", workers=eval_workers)
    result = {
        "variant": test.variant,
        "seed": cfg.optim.seed,
        "steps": steps,
        "ckpt": str(ckpt),
        "test": test.summary,
        "train_wall_s": wall,
        "load_before": load_before,
        "load_after": os.getloadavg(),
    }
    s = test.summary
    load = f"load {load_before[1]:.2f} -> {result['load_after'][1]:.2f}"
    print(f"{run_dir.name}: {wall / 60:.1f} min ({load}); "
          f"test rotation {s['re_deg_median']:.2f} deg median, ADD@0.02m {pct(s['add_0.02m'])} %, "
          f"ADD@0.1d {pct(s['add_0.1d'])} %", flush=True)  # fmt: skip
    return result
