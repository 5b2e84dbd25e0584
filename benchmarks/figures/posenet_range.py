"""posenet accuracy against the attitude range: the corridor control widened, at equal compute.

    python benchmarks/figures/posenet_range.py --out OUT [--angles 20 45 90 180] [--steps 1260] [--model NAME]

For each cone half-angle A renders the corridor control's set with only the attitude range changed
(benchmarks/figures/posenet_control.py's scene: 2,400 Mitsuba images at 320x240, seed 7, the target 120-180 px
across; `pose.max_angle_deg` A and `pose.roll_deg` [-A, A], so 180 is every attitude) into
OUT/cone-A/data. The seed fixes every other draw (sun, sky, distance, occluders, split), so the sets
differ in the target's attitude alone. Then trains the CPU recipe (GDR-Net, `--config smoke`, the
ablation's schedule: benchmarks/posenet_ablation.py, seed 0) for --steps on each and tests it on the
test split (480 images, ground-truth boxes). Beside each point, what the corridor alone scores: the
nominal attitude as the estimate (harness.pose.prior). --model renders another target (a bundled model's
name, e.g. the asymmetric smallsat, or a mesh) into OUT/NAME-cone-A instead, all else equal.

Resumable: renders resume, a finished run (its result.json) is kept. After each run OUT/range.json and
OUT/range.png (test rotation median and ADD@0.1d against the half-angle) are rewritten. On 2 cores:
about 18 min of rendering and 12-15 min of training per point.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import SEED, parser, pct, positive, pyplot, run_script
from harness.pose import (
    ABLATION_STEPS,
    CHANCE_RE_DEG,
    CONTROL_N,
    CONTROL_SCENE,
    prior,
    render_control,
    run_config,
    train_one,
)

from scgen.io.atomic import atomic_write_text

ANGLES = (20.0, 45.0, 90.0, 180.0)
VARIANT = "gdrnet"  # the ablation's pick on a CPU (docs/benchmarks.md)


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--out", type=Path, required=True, help="Output: cone-A/, range.json, range.png.")
    ap.add_argument("--angles", type=float, nargs="+", default=list(ANGLES), help="Half-angles (deg).")
    ap.add_argument("--steps", type=positive, default=ABLATION_STEPS, help="Steps of each run [%(default)s].")
    ap.add_argument("--seed", type=int, default=0, help="Training seed [%(default)s].")
    ap.add_argument("--model", help="Target: a bundled model's name or a mesh [the spacecraft].")
    return ap.parse_args()


def scene(angle: float) -> dict[str, Any]:
    """The control's scene with a cone of half-angle `angle` and the roll range to match."""
    return {
        **CONTROL_SCENE,
        "pose": {**CONTROL_SCENE["pose"], "max_angle_deg": angle, "roll_deg": [-angle, angle]},
    }


def point(out: Path, angle: float, steps: int, seed: int, model: str | None) -> dict[str, Any]:
    """Render (or resume) the set of half-angle `angle` of `model`, train one run on it and test it."""
    folder = out / (f"cone-{angle:g}" if model is None else f"{Path(model).stem}-cone-{angle:g}")
    data = render_control(folder, CONTROL_N, SEED, scene(angle), model)
    cfg = run_config(VARIANT, seed, steps, data)
    result = train_one(data, data.parent / f"run-{VARIANT}-seed{seed}", cfg, steps, eval_workers=0)
    return {"angle": angle, "steps": steps, "seed": seed, "model": model or "spacecraft",
            "train_wall_s": result["train_wall_s"], "test": result["test"], "prior": prior(data)}  # fmt: skip


def plot(path: Path, points: list[dict[str, Any]], steps: int) -> None:
    plt = pyplot()
    points = sorted(points, key=lambda p: p["angle"])
    x = [p["angle"] for p in points]
    fig, ax = plt.subplots(figsize=(8, 5))
    ax.plot(x, [p["test"]["re_deg_median"] for p in points], "o-", color="tab:red", label="rotation median")
    ax.plot(x, [p["prior"]["re_deg_median"] for p in points], "o:", color="tab:red", alpha=0.5,
            label="the nominal attitude alone")  # fmt: skip
    ax.axhline(CHANCE_RE_DEG, color="grey", ls="--", alpha=0.6)
    ax.text(x[0], CHANCE_RE_DEG, f" a random rotation: {CHANCE_RE_DEG:.0f} deg", color="grey",
            va="bottom")  # fmt: skip
    ax.set_xlabel("attitude range: cone half-angle = roll half-range (deg); 180 = every attitude")
    ax.set_ylabel("test rotation error, median (deg)", color="tab:red")
    ax.set_ylim(0, 140)
    ax.set_xticks(x)
    ax2 = ax.twinx()
    ax2.plot(x, [100 * p["test"]["add_0.1d"] for p in points], "s-", color="tab:blue", label="ADD@0.1d")
    ax2.set_ylabel("test ADD@0.1d (%)", color="tab:blue")
    ax2.set_ylim(0, 100)
    lines = [h for a in (ax, ax2) for h in a.get_legend_handles_labels()[0]]
    ax.legend(lines, [h.get_label() for h in lines], loc="center right", fontsize=8)
    ax.grid(True, alpha=0.3)
    ax.set_title(f"{points[0]['model']}: GDR-Net, CPU recipe, {steps} steps each ({CONTROL_N:,} images a "
                 f"set); {points[0]['test']['n']} test images")  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(args: argparse.Namespace) -> list[dict[str, Any]]:
    args.out.mkdir(parents=True, exist_ok=True)
    points = []
    for angle in args.angles:  # in the order given: the most telling point first, if time is short
        p = point(args.out, angle, args.steps, args.seed, args.model)
        points.append(p)
        atomic_write_text(args.out / "range.json", json.dumps({"points": points}, indent=1) + "\n")
        plot(args.out / "range.png", points, args.steps)
        s = p["test"]
        print(f"{angle:g} deg: rotation median {s['re_deg_median']:.1f} deg (nominal alone "
              f"{p['prior']['re_deg_median']:.1f}), ADD@0.1d {pct(s['add_0.1d'])} %, ADD-S@0.1d "
              f"{pct(s['adds_0.1d'])} %, translation alone {pct(s['te_0.1d'])} %", flush=True)  # fmt: skip
    print(f"wrote {args.out / 'range.json'} and {args.out / 'range.png'}")
    return points


if __name__ == "__main__":
    run_script(run, parse_args())
