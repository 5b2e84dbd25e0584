"""GDR-Net's recipe details and the field's augmentation, each measured on the CPU preset at equal compute.

Every variant trains the `smoke` config for the same number of epochs (the same steps, batch and lr
schedule) with one detail changed, through the learning benchmark (benchmarks/figures/posenet_learning.py,
into OUT/VARIANT), and is evaluated on the test split (scene-factor combinations never seen in training):

- baseline: the smoke preset as it is;
- grad-centralization: optim.grad_centralization (Ranger's, GDR-Net's `use_gc`);
- weight-decay-0: optim.weight_decay 0 (GDR-Net's; the paper's is 0.05);
- decay-norms-biases: optim.decay_norms_biases (Ranger decays them too; posenet's default does not);
- gdrnet-occlusion: data.augment gdrnet-occlusion and data.truncate_fg (GDR-Net's occlusion configs);
- ideal-camera and ideal-camera+spnv2: trained on the same scenes rendered through the `ideal` camera,
  without and with data.augment spnv2, both tested on the `default` camera's test split.

Renders the two datasets (1000 samples, seed 7, 320x240, Mitsuba; the learning benchmark's) into
OUT/data-default and OUT/data-ideal unless --data / --ideal-data name them. A variant whose
OUT/VARIANT/learning.json exists is not trained again, so an interrupted run goes on where it stopped.
Prints one table, a column per variant: test figures, the train split's rotation error and the mean of each
loss term over the last 10 % of the steps; writes OUT/recipe_details.json.

    python benchmarks/probes/recipe_details.py --out /tmp/recipe [--epochs 20]

Each variant is one CPU training (20 epochs: about 10 min on 2 idle cores).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import BACKEND, RENDER_N, RESOLUTION, SEED, WORKERS, parser, run_script

from posenet import evaluate
from posenet.evaluation.evaluate import format_table
from posenet.training.losses import LOSS_TERMS
from posenet.training.train import LOG_FILE
from scgen.io.atomic import atomic_write_text
from scgen.run.runner import RenderJob, run_render

LEARNING = Path(__file__).resolve().parents[1] / "figures" / "posenet_learning.py"
# variant -> (config overrides of the smoke preset, camera of its training renders)
VARIANTS: dict[str, tuple[dict[str, Any], str]] = {
    "baseline": ({}, "default"),
    "grad-centralization": ({"optim": {"grad_centralization": True}}, "default"),
    "weight-decay-0": ({"optim": {"weight_decay": 0.0}}, "default"),
    "decay-norms-biases": ({"optim": {"decay_norms_biases": True}}, "default"),
    "gdrnet-occlusion": ({"data": {"augment": "gdrnet-occlusion", "truncate_fg": True}}, "default"),
    "ideal-camera": ({}, "ideal"),
    "ideal-camera+spnv2": ({"data": {"augment": "spnv2"}}, "ideal"),
}
# (label, split, summary key, format) of the table's rows
FIGURES = (
    ("test rotation error, median (deg)", "test", "re_deg_median", "{:.1f}"),
    ("test turned poses > 135 deg (%)", "test", "turned", "{:.1%}"),
    ("test translation error, median (m)", "test", "te_m_median", "{:.4f}"),
    ("test depth error, median (% of depth)", "test", "tz_rel_median", "{:.2%}"),
    ("test ADD@0.1d (%)", "test", "add_0.1d", "{:.1%}"),
    ("test ADD@0.1d, translation alone (%)", "test", "te_0.1d", "{:.1%}"),
    ("test ADD@0.1d, rotation alone (%)", "test", "add_rot_0.1d", "{:.1%}"),
    ("train rotation error, median (deg)", "train", "re_deg_median", "{:.1f}"),
)


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--out", type=Path, required=True, help="Output folder.")
    ap.add_argument("--data", type=Path, default=None, help="The default camera's dataset [render one].")
    ap.add_argument("--ideal-data", type=Path, default=None, help="The same scenes through the ideal camera.")
    ap.add_argument("--epochs", type=int, default=20, help="Epochs of every variant's schedule [20].")
    ap.add_argument("--variant", action="append", choices=list(VARIANTS), help="Only these (repeatable).")
    return ap.parse_args()


def dataset(folder: Path | None, out: Path, camera: str) -> Path:
    """`folder`, or the learning benchmark's set rendered through `camera` into OUT/data-CAMERA."""
    if folder is not None:
        return folder
    job = RenderJob(out=out / f"data-{camera}", n=RENDER_N, seed=SEED, backend=BACKEND, camera=camera,
                    resolution=RESOLUTION, workers=WORKERS)  # fmt: skip
    run_render(job, progress=True)
    return job.out


def train_variant(name: str, out: Path, data: Path, epochs: int) -> dict[str, Any]:
    """Train one variant through the learning benchmark (unless its learning.json exists); its run."""
    folder = out / name
    result = folder / "learning.json"
    if not result.exists():
        overrides, _ = VARIANTS[name]
        config = out / "configs" / f"{name}.yaml"
        config.parent.mkdir(parents=True, exist_ok=True)
        config.write_text(yaml.safe_dump({"preset": "smoke", **overrides}))
        cmd = [sys.executable, str(LEARNING), "--out", str(folder), "--data", str(data)]
        cmd += ["--config", str(config), "--epochs", str(epochs), "--eval-every", str(10**9), "--overwrite"]
        print(f"{name}: training ({' '.join(cmd[1:])})", flush=True)
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return json.loads(result.read_text())["runs"][0]


def last_losses(run: dict[str, Any]) -> dict[str, float]:
    """Mean of each loss term over the last 10 % of the run's steps (its training log)."""
    rows = [json.loads(line) for line in (Path(run["run"]) / LOG_FILE).read_text().splitlines()]
    tail = rows[-max(1, len(rows) // 10) :]
    terms = [term for term in ("loss", *LOSS_TERMS) if term in tail[0]]
    return {term: float(np.mean([r[term] for r in tail])) for term in terms}


def run(args: argparse.Namespace) -> None:
    args.out.mkdir(parents=True, exist_ok=True)
    names = args.variant or list(VARIANTS)
    data = {"default": dataset(args.data, args.out, "default")}
    if any(VARIANTS[n][1] == "ideal" for n in names):
        data["ideal"] = dataset(args.ideal_data, args.out, "ideal")
    figures: dict[str, dict[str, Any]] = {}
    for name in names:
        camera = VARIANTS[name][1]
        run = train_variant(name, args.out, data[camera], args.epochs)
        final = dict(run["final"])
        if camera != "default":  # tested on the default camera's renders of the same test scenes
            final["test"] = evaluate(data["default"], Path(run["ckpt"]), "test").summary
        figures[name] = {"steps": run["steps"], **final, "losses": last_losses(run)}
    steps = {f["steps"] for f in figures.values()}
    print(f"\nequal compute: {', '.join(map(str, sorted(steps)))} steps of batch 8 each (smoke preset, "
          f"{args.epochs} epochs); test split of {data['default']}")  # fmt: skip
    rows = [[label, *(fmt.format(figures[n][split][k]) for n in names)] for label, split, k, fmt in FIGURES]
    for term in next(iter(figures.values()))["losses"]:
        label = f"train loss, {'total' if term == 'loss' else term}, last 10 % of steps"
        rows.append([label, *(f"{figures[n]['losses'][term]:.3f}" for n in names)])
    print(format_table(["figure", *names], rows))
    atomic_write_text(args.out / "recipe_details.json", json.dumps(figures, indent=1) + "\n")
    print(f"wrote {args.out / 'recipe_details.json'}")


if __name__ == "__main__":
    run_script(run, parse_args())
