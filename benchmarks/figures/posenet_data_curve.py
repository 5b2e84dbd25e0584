"""posenet accuracy against data: the CPU recipe at equal compute on nested training sets, one test set.

    python benchmarks/figures/posenet_data_curve.py --out /tmp/curve

Renders one large set with the learning benchmark's settings (Mitsuba, 320x240, seed 7, the default
camera, uniform SO(3) attitudes; 30,000 samples: 21,000 / 3,000 / 6,000 by factor combinations) into
OUT/data, then for each training-set size (700, 2,100, 7,000 and 21,000 images: `data.train_images`, so
each set holds the smaller ones) trains the CPU recipe (`posenet train --config smoke`) for the same
10,440 steps into OUT/run-N and tests it on one fixed subset of the test split (1,000 images, ground-truth
boxes). After each point OUT/curve.json and OUT/data_curve.png are rewritten, so an interrupted run keeps
what it measured; re-running resumes the render and skips the points already in curve.json. On 2 cores:
about 50 min of rendering and 30-50 min per point.

The plot: test rotation error median and ADD@0.1d against training images (log axis), the paper's
35,000 training images marked.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import BACKEND, RESOLUTION, SEED, WORKERS, parser, pyplot, run_script
from harness.pose import CHANCE_RE_DEG, schedule

from posenet import evaluate, train
from posenet.config import load_config
from posenet.data.dataset import first_images
from posenet.data.layout import scan_split
from posenet.training.train import LAST
from scgen.io.atomic import atomic_write_text
from scgen.run.runner import RenderJob, run_render

N, SIZES, TEST_N, STEPS = 30000, (700, 2100, 7000, 21000), 1000, 10440
PAPER_TRAIN_IMAGES = 35000  # the paper's training set (35,000 images at 640x480, 300 epochs)
FIGURES = ("re_deg_median", "add_0.1d", "add_rot_0.1d", "te_0.1d", "turned", "tz_rel_median", "te_m_median")


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--out", type=Path, required=True, help="Output folder: data/, run-N/, curve.json, PNG.")
    ap.add_argument("--n", type=int, default=N, help="Samples to render [%(default)s].")
    ap.add_argument(
        "--sizes",
        type=int,
        nargs="+",
        default=list(SIZES),
        help="Training images per point, trained in this order.",
    )
    ap.add_argument("--test-n", type=int, default=TEST_N, help="Test images evaluated [%(default)s].")
    ap.add_argument("--steps", type=int, default=STEPS, help="Training steps per point [%(default)s].")
    return ap.parse_args()


def render(out: Path, n: int) -> Path:
    data = out / "data"
    job = RenderJob(out=data, n=n, seed=SEED, backend=BACKEND, resolution=RESOLUTION, workers=WORKERS)
    s = run_render(job, progress=True)
    print(f"dataset: {data}, rendered {s['rendered']}, reused {s['skipped']}, {s['total_s']:.0f} s; "
          + ", ".join(f"{k} {v}" for k, v in s["splits"].items()))  # fmt: skip
    return data


def held_out_images(data: Path, n: int) -> set[int]:
    """The fixed held-out subset: `n` test images (with a visible target) in the same fixed order."""
    instances = [i for i in scan_split(data, "test", 1) if i.px_count_visib > 0]
    return {i.im_id for i in first_images(instances, min(n, len({i.im_id for i in instances})))}


def train_point(data: Path, out: Path, size: int, steps: int) -> Path:
    """The CPU recipe on the first `size` training images for `steps` steps (its schedule ending there);
    resumes a run that stopped part-way."""
    cfg = load_config("smoke")
    cfg.data.train_images = size
    n_train, per_epoch, _ = schedule(data, cfg)
    cfg.optim.epochs = max(1, math.ceil(steps / per_epoch))
    run = out / f"run-{size}"
    print(f"\n{size} training images ({n_train} instances), {steps} steps ({cfg.optim.epochs} epochs)")
    return train(data, run, cfg, resume=(run / LAST).exists(), max_steps=steps)


def plot(path: Path, points: list[dict[str, Any]], test_n: int, steps: int) -> None:
    plt = pyplot()
    x = [p["train_images"] for p in points]
    fig, ax = plt.subplots(figsize=(8, 5))
    ax.plot(
        x, [p["test"]["re_deg_median"] for p in points], "o-", color="tab:red", label="rotation error median"
    )
    ax.set_xscale("log")
    ax.set_xlabel("training images (log scale)")
    ax.set_ylabel("test rotation error, median (deg)", color="tab:red")
    ax.set_ylim(0, 1.1 * max([p["test"]["re_deg_median"] for p in points] + [CHANCE_RE_DEG]))
    ax.axhline(CHANCE_RE_DEG, color="tab:red", ls=":", alpha=0.6)
    left = min([*x, 700]) / 1.5
    ax.text(left, CHANCE_RE_DEG, f" a random rotation: {CHANCE_RE_DEG:.0f} deg", color="tab:red", va="bottom",
            alpha=0.8)  # fmt: skip
    ax.axvline(PAPER_TRAIN_IMAGES, color="grey", ls="--")
    ax.text(PAPER_TRAIN_IMAGES, ax.get_ylim()[1] * 0.95, "paper: 35,000 ", color="grey", va="top", ha="right")
    ax2 = ax.twinx()
    ax2.plot(x, [100 * p["test"]["add_0.1d"] for p in points], "s-", color="tab:blue", label="ADD@0.1d")
    ax2.set_ylabel("test ADD@0.1d (%)", color="tab:blue")
    ax2.set_ylim(0, 100)
    ax.set_xlim(left, PAPER_TRAIN_IMAGES * 1.5)
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title(f"CPU recipe, {steps} steps each; {test_n} held-out test images, GT boxes")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(args: argparse.Namespace) -> list[dict[str, Any]]:
    args.out.mkdir(parents=True, exist_ok=True)
    data = render(args.out, args.n)
    held_out = held_out_images(data, args.test_n)
    curve_file = args.out / "curve.json"
    points = json.loads(curve_file.read_text())["points"] if curve_file.exists() else []
    for size in args.sizes:  # in the order given: the most telling point first, if time is short
        if any(p["train_images"] == size for p in points):
            continue
        ckpt = train_point(data, args.out, size, args.steps)
        summary = evaluate(data, ckpt, "test", image_ids=held_out).summary
        points = sorted([*points, {"train_images": size, "steps": args.steps, "test": summary}],
                        key=lambda p: p["train_images"])  # fmt: skip
        atomic_write_text(curve_file, json.dumps({"data": str(data), "test_images": len(held_out),
                                                  "points": points}, indent=1) + "\n")  # fmt: skip
        plot(args.out / "data_curve.png", points, len(held_out), args.steps)
        print(f"{size} images: " + ", ".join(f"{k} {summary[k]:.4g}" for k in FIGURES))
    if points:
        plot(args.out / "data_curve.png", points, len(held_out), args.steps)
    if len(points) >= 2:  # the trend of the median rotation error in log(images), for the reading
        x = np.log10([p["train_images"] for p in points])
        slope = np.polyfit(x, [p["test"]["re_deg_median"] for p in points], 1)[0]
        print(f"test rotation error median: {slope:+.1f} deg per tenfold training images")
    print(f"wrote {curve_file} and {args.out / 'data_curve.png'}")
    return points


if __name__ == "__main__":
    run_script(run, parse_args())
