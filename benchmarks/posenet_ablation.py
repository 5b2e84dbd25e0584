"""posenet ablation: the paper's Table 4 and Table 6 protocol at CPU scale, on the corridor control's data.

    python benchmarks/posenet_ablation.py --out OUT [--data CONTROL/data] [--steps 1260] [--seeds 0 1 2]

Trains each --variant (default GDR-Net and GAP-GDRNet, both on the packaged ImageNet Lite0: the paper's
backbone-control comparison) once per training seed with the CPU recipe (`--config smoke`), every run
with the same schedule (the recipe's cosine fitted to --steps) and, per seed, the same data order and
augmentation draws (the loader is seeded by optim.seed alone, not by the network's draws). Each
finished run is evaluated on the test split (factor combinations never seen in training, ground-truth
boxes). Then:

- Table 4: per variant, the mean and spread (sample standard deviation) over the seeds of the rotation
  error (mean and median), translation error, ADD@0.02 m and ADD@0.1d; and per seed the paired
  difference of each variant against the first, with its mean and a 95 % t interval over the seeds.
- Table 6: ADD@0.02 m per factor group of the test split (posenet.evaluation.evaluate.by_factor, each
  column the mean over that variant's seeds), the group sizes beside them; groups under 500
  images are marked.

Runs train one at a time in the order seed 0 of every variant, then seed 1, ..., so that an interrupted
benchmark leaves paired seeds. Re-running with the same --out resumes: a finished run (its result.json)
is kept, an unfinished one resumes from its last.pt. Each run records its wall time and the machine's
load average before and after. Without --data the control set is rendered into OUT/data
(benchmarks/figures/posenet_control.py's scene: 2,400 Mitsuba images at 320x240, seed 7).

Writes OUT/run-VARIANT-seedS/ (the run and its result.json) and OUT/ablation.json (every figure printed).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
from pathlib import Path
from typing import Any

from harness import parser, pct, positive, run_script
from harness.pose import ABLATION_STEPS, render_control, run_config, train_one

from posenet.errors import PosenetError
from posenet.evaluation.evaluate import by_factor, format_table
from scgen.dataset.stats import sample_groups
from scgen.io.atomic import atomic_write_text

VARIANTS = ("gdrnet", "gap-gdrnet")
SEEDS = (0, 1, 2)
GROUP_N = 500  # the paper's images per factor group
# (summary key, column label, scale) of Table 4
FIGURES = (
    ("re_deg", "e_R mean (deg)", 1.0),
    ("re_deg_median", "e_R median (deg)", 1.0),
    ("te_m", "e_T mean (m)", 1.0),
    ("add_0.02m", "ADD@0.02m (%)", 100.0),
    ("add_0.1d", "ADD@0.1d (%)", 100.0),
)
T_975 = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571}  # Student's t, two-sided 95 %


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--out", type=Path, required=True, help="Output: run-VARIANT-seedS/, ablation.json.")
    ap.add_argument("--data", type=Path, default=None, help="The control's dataset [rendered into OUT/data].")
    ap.add_argument("--variant", action="append", default=None, help="Repeatable [gdrnet, gap-gdrnet].")
    ap.add_argument("--seeds", type=int, nargs="+", default=list(SEEDS), help="Training seeds [0 1 2].")
    ap.add_argument("--steps", type=positive, default=ABLATION_STEPS, help="Steps of each run [%(default)s].")
    ap.add_argument("--eval-workers", type=int, default=0, help="Evaluation loader processes [0].")
    return ap.parse_args()


def spread(values: list[float]) -> str:
    """'mean ± sd' (sd over the seeds; the mean alone for one seed)."""
    mean = statistics.fmean(values)
    return f"{mean:.3g}" if len(values) < 2 else f"{mean:.3g} ± {statistics.stdev(values):.2g}"


def paired(base: list[dict[str, Any]], other: list[dict[str, Any]], key: str, scale: float) -> dict[str, Any]:
    """Per seed other - base of one figure, with the mean and a 95 % t interval over the seeds."""
    by_seed = {r["seed"]: r["test"][key] * scale for r in base}
    diffs = [r["test"][key] * scale - by_seed[r["seed"]] for r in other if r["seed"] in by_seed]
    out: dict[str, Any] = {"diffs": diffs, "mean": statistics.fmean(diffs) if diffs else None}
    if len(diffs) >= 2:
        half = T_975.get(len(diffs) - 1, 2.0) * statistics.stdev(diffs) / math.sqrt(len(diffs))
        out["ci95"] = [out["mean"] - half, out["mean"] + half]
    return out


def table4(results: dict[str, list[dict[str, Any]]]) -> tuple[str, dict[str, Any]]:
    """Table 4 (mean ± sd over the seeds) and the paired differences against the first variant."""
    rows = [[v, str(len(rs)), *(spread([r["test"][k] * s for r in rs]) for k, _, s in FIGURES)]
            for v, rs in results.items()]  # fmt: skip
    text = format_table(["variant", "seeds", *(label for _, label, _ in FIGURES)], rows)
    base_name, *others = results
    diffs = {o: {k: paired(results[base_name], results[o], k, s) for k, _, s in FIGURES} for o in others}
    for o, figs in diffs.items():
        cells = []
        for k, label, _ in FIGURES:
            d = figs[k]
            ci = f" [{d['ci95'][0]:+.3g}, {d['ci95'][1]:+.3g}]" if "ci95" in d else ""
            cells.append(f"{label} {', '.join(f'{x:+.3g}' for x in d['diffs'])} (mean {d['mean']:+.3g}{ci})")
        text += f"\n{o} - {base_name}, per seed: " + "; ".join(cells)
    return text, diffs


def table6(data: Path, results: dict[str, list[dict[str, Any]]], out: Path, workers: int) -> tuple[str, dict]:
    """Table 6: ADD@0.02 m per factor group of the test split, each variant's seeds averaged."""
    groups_file = out / f"groups_test_n{GROUP_N}_s0.json"
    atomic_write_text(groups_file, json.dumps(sample_groups(data, "test", GROUP_N, 0), indent=1) + "\n")
    ckpts = [Path(r["ckpt"]) for rs in results.values() for r in rs]
    factors = by_factor(data, ckpts, groups_file, "test", workers=workers)
    cols = factors["columns"]
    rows = [[f"{f}/{g}", f"{n}{'' if n is not None and n >= GROUP_N else ' (<500)'}",
             *(pct(vals[c]) for c in cols)]
            for f, gs in factors["groups"].items() for g, vals in gs.items()
            for n in [factors["n"][f][g]]]  # fmt: skip
    return format_table(["ADD@0.02m (%)", "n", *cols], rows), factors


def run(args: argparse.Namespace) -> None:
    variants = args.variant or list(VARIANTS)
    if len(set(variants)) < len(variants) or len(set(args.seeds)) < len(args.seeds):
        raise PosenetError("--variant and --seeds must not repeat a value")
    args.out.mkdir(parents=True, exist_ok=True)
    data = args.data if args.data is not None else render_control(args.out)
    if not data.is_dir():
        raise PosenetError(f"--data {data} is not a folder")
    results: dict[str, list[dict[str, Any]]] = {v: [] for v in variants}
    for seed in args.seeds:
        for v in variants:
            cfg = run_config(v, seed, args.steps, data)
            run_dir = args.out / f"run-{v}-seed{seed}"
            results[v].append(train_one(data, run_dir, cfg, args.steps, args.eval_workers))
    t4, diffs = table4(results)
    print(f"\nTable 4 at {args.steps} steps (test split, ground-truth boxes; mean ± sd over seeds "
          f"{', '.join(map(str, args.seeds))}):\n{t4}")  # fmt: skip
    t6, factors = table6(data, results, args.out, args.eval_workers)
    print(f"\nTable 6: test ADD@0.02m by factor group, each column the mean over its seeds:\n{t6}")
    report = {"data": str(data), "steps": args.steps, "seeds": args.seeds, "runs": results,
              "paired": diffs, "by_factor": factors}  # fmt: skip
    atomic_write_text(args.out / "ablation.json", json.dumps(report, indent=1) + "\n")
    print(f"wrote {args.out / 'ablation.json'}")


if __name__ == "__main__":
    run_script(run, parse_args())
