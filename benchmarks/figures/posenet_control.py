"""posenet control: the CPU recipe on a problem it can learn at CPU scale, tested on the held-out split.

    python benchmarks/figures/posenet_control.py --out /tmp/control

Renders 2400 Mitsuba samples at 320x240 (seed 7, split by factor combinations: 1680 / 240 / 480) whose
target attitude lies in a rendezvous corridor (`pose.distribution: cone`: the line of sight within 20 deg
of the nominal one, roll within +-20 deg) and whose target is close (its bounding sphere spans 240-360 px
at the 640-px reference camera, 120-180 px here), then trains the CPU recipe (`posenet train --config
smoke`, GDR-Net on the ImageNet Lite0) for the learning benchmark's 10,440 steps and tests the final
checkpoint on the test split at ground-truth boxes. About 5 min of rendering and 35-50 min of training
on 2 cores.

Why these settings:
- The corridor: a chaser closing on an attitude-held target sees it from inside an approach corridor
  about the target's docking or inspection axis (final-approach corridors are cones of about 10-20 deg
  half-angle), with its roll about the line of sight held to the plan; 20 deg of each is a generous one.
- The distance: ADD@0.1d passes the translation alone when |dt| < 0.1 d, i.e. a relative depth error
  below 0.1 d / z, a tenth of the target's angular size. At the default range (0.4-2 m for the 0.2 m
  bundled model) that is 1-5 %; here 4-6 %, the close-range inspection a docking camera sees.

The floors (issue 40): test median rotation error <= 5 deg, ADD@0.1d >= 50 %, translation alone
(ADD@0.1d of the predicted translation at the true rotation) >= 60 %. Beside them, what knowing only the
corridor gives: the nominal attitude (at the true translation) and the training split's median depth
(along the true ray), scored like a prediction.

Where a floor is missed it looks for the cause (also alone: --diagnose, on OUT/data): PnP (OpenCV) on
training items' own dense targets (ground-truth xyz in the visible mask and the RoI's 2D coordinates, DZI
on) must give back their pose, and SITE's decoding their translation, so crop, K, xyz normalisation and
Patch-PnP's input channels agree with the labels; and the recipe, without augmentation, must overfit 8
training images (400 steps into OUT/overfit).

Writes OUT/report.json: the test split's summary under `test` (posenet eval's keys: re_deg_median,
add_0.1d, te_0.1d, ...), the train split's under `train`, the floors, the prior's figures, the dataset,
the timing and any diagnosis; and OUT/learning_curve-gdrnet.png. Re-running with the same --out resumes
the render.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import shutil
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import BACKEND, SEED, fresh_run, parser, pct, run_script
from harness.pose import (
    CONTROL_N,
    CONTROL_RESOLUTION,
    CONTROL_SCENE,
    floor_lines,
    floor_rows,
    prior,
    render_control,
    run_folder,
    schedule,
    train_and_follow,
)

from posenet import evaluate, train
from posenet.config import load_config
from posenet.data import open_split
from posenet.evaluation.metrics import rotation_error_deg, translation_error
from posenet.geometry import roi_translation
from posenet.predict.ransac import MIN_POINTS
from scgen.io.atomic import atomic_write_text

LEARNING_STEPS = 10440  # the CPU recipe's schedule on the learning benchmark (120 epochs x 87 steps)
# (split, figure, bound, "max" | "min")
FLOORS = (
    ("test", "re_deg_median", 5.0, "max"),
    ("test", "add_0.1d", 0.50, "min"),
    ("test", "te_0.1d", 0.60, "min"),
)


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--out", type=Path, required=True, help="Output folder: data/, run-gdrnet/, report.json.")
    ap.add_argument("--n", type=int, default=CONTROL_N, help="Samples to render [%(default)s].")
    ap.add_argument("--seed", type=int, default=SEED, help="Dataset seed [%(default)s].")
    ap.add_argument("--steps", type=int, default=LEARNING_STEPS, help="Training steps [%(default)s].")
    ap.add_argument("--eval-every", type=int, default=2610, help="Test evaluation interval [%(default)s].")
    ap.add_argument("--overwrite", action="store_true", help="Delete an existing OUT/run-gdrnet first.")
    ap.add_argument("--diagnose", action="store_true", help="Only the diagnosis, on OUT/data: no training.")
    return ap.parse_args()


def targets_give_the_pose(data: Path, items: int = 200) -> dict[str, float]:
    """PnP on the dense targets of `items` training items (augmented: DZI on) against their GT pose, and
    SITE's decoding of their SITE target against their GT translation."""
    cfg = load_config("smoke")
    ds = open_split(data, "train", cfg.data, cfg.model_config(), train=True)
    re, te, site = [], [], []
    for idx in range(0, len(ds), max(1, len(ds) // items)):
        it = ds[(1, idx)]
        visible = it["roi_mask_visib"][0].numpy() > 0
        # Patch-PnP's own input channels: the xyz target and the RoI's 2D coordinates (u / W, v / H)
        points = (it["roi_xyz"].numpy().transpose(1, 2, 0)[visible] - 0.5) * ds.obj.extent
        pixels = it["roi_coord2d"].numpy().transpose(1, 2, 0)[visible] * ds.instances[idx].image_size
        if len(points) < MIN_POINTS:
            continue
        # every pixel in one least-squares solve (EPnP, then refined): a consistency check, where posenet's
        # RANSAC (2 px inliers) throws away the few pixels of a thin silhouette and with them the pose
        points, pixels, K = (
            points.astype(np.float64),
            pixels.astype(np.float64),
            it["K"].numpy().astype(float),
        )
        _, rvec, tvec = cv2.solvePnP(points, pixels, K, None, flags=cv2.SOLVEPNP_EPNP)
        _, rvec, tvec = cv2.solvePnP(points, pixels, K, None, rvec, tvec, True, cv2.SOLVEPNP_ITERATIVE)
        R, t = torch.from_numpy(cv2.Rodrigues(rvec)[0]), torch.from_numpy(tvec[:, 0])
        re.append(float(rotation_error_deg(R, it["R"].double())))
        te.append(float(translation_error(t, it["t"].double())))
        batch = {k: it[k][None] for k in ("K", "crop_center", "box_wh", "resize_ratio")}
        site.append(float((roi_translation(it["site"][None], batch)[0] - it["t"]).norm()))
    return {"items": len(re), "pnp_re_deg_median": float(np.median(re)), "pnp_re_deg_max": max(re),
            "pnp_te_m_median": float(np.median(te)), "pnp_te_m_max": max(te),
            "site_te_m_max": max(site)}  # fmt: skip


def overfit(data: Path, out: Path, images: int = 8, steps: int = 400) -> dict[str, float]:
    """The CPU recipe without augmentation on `images` training images (one batch) for `steps` steps,
    evaluated on those images."""
    cfg = load_config("smoke")
    cfg.data = dataclasses.replace(cfg.data, train_images=images, dzi_prob=0.0, color_prob=0.0, bg_prob=0.0)
    cfg.optim.batch_size, cfg.optim.epochs = images, steps
    shutil.rmtree(out, ignore_errors=True)
    ckpt = train(data, out, cfg)
    ids = {i.im_id for i in open_split(data, "train", cfg.data, cfg.model_config(), train=True).instances}
    s = evaluate(data, ckpt, "train", image_ids=ids).summary
    keys = ("n", "re_deg_median", "te_m_median", "tz_rel_median", "add_0.1d")
    return {"steps": steps, **{k: s[k] for k in keys}}


def diagnose(data: Path, out: Path) -> dict[str, Any]:
    """The checks a missed floor calls for (the module's docstring), printed and returned."""
    targets = targets_give_the_pose(data)
    print(f"diagnosis: PnP on the GT dense targets of {targets['items']} training items: rotation error "
          f"median {targets['pnp_re_deg_median']:.3f} deg (max {targets['pnp_re_deg_max']:.2f}), translation "
          f"median {1000 * targets['pnp_te_m_median']:.2f} mm (max {1000 * targets['pnp_te_m_max']:.1f}); "
          f"SITE decoding off by at most {1000 * targets['site_te_m_max']:.4f} mm")  # fmt: skip
    fit = overfit(data, out / "overfit")
    print(f"diagnosis: overfitting {fit['n']} training images ({fit['steps']} steps): rotation error median "
          f"{fit['re_deg_median']:.2f} deg, translation {1000 * fit['te_m_median']:.1f} mm, depth "
          f"{pct(fit['tz_rel_median'])} %, ADD@0.1d {pct(fit['add_0.1d'])} %")  # fmt: skip
    return {"targets_give_the_pose": targets, "overfit": fit}


def run(args: argparse.Namespace) -> dict[str, Any]:
    args.out.mkdir(parents=True, exist_ok=True)
    data = render_control(args.out, args.n, args.seed)
    if args.diagnose:
        diagnosis = diagnose(data, args.out)
        atomic_write_text(args.out / "diagnosis.json", json.dumps(diagnosis, indent=1) + "\n")
        return diagnosis
    cfg = load_config("smoke")
    cfg.optim.epochs = max(1, math.ceil(args.steps / schedule(data, cfg)[1]))
    fresh_run(run_folder(args.out, cfg), args.overwrite)
    result = train_and_follow(data, args.out, cfg, "smoke", FLOORS, args.steps, args.eval_every)
    test = result["final"]["test"]
    report = {
        "test": test,
        "train": result["final"]["train"],
        "floors": floor_rows({"test": test}, FLOORS),
        "prior": prior(data, cfg.data.obj_id),
        "dataset": {
            "path": str(data),
            "n": args.n,
            "seed": args.seed,
            "backend": BACKEND,
            "resolution": "x".join(map(str, CONTROL_RESOLUTION)),
            "scene": CONTROL_SCENE,
        },  # fmt: skip
        "training": {k: result[k] for k in ("steps", "schedule_steps", "train_instances", "timing", "curve")},
    }
    if not all(f["met"] for f in report["floors"]):
        report["diagnosis"] = diagnose(data, args.out)
    atomic_write_text(args.out / "report.json", json.dumps(report, indent=1) + "\n")
    p = report["prior"]
    print("\nthe corridor alone (nominal attitude, train median depth) on the test split: rotation median "
          f"{p['re_deg_median']:.2f} deg, rotation alone {pct(p['add_rot_0.1d'])} %, translation alone "
          f"{pct(p['te_0.1d'])} %, depth error median {pct(p['tz_rel_median'])} %")  # fmt: skip
    for line in floor_lines({"test": test}, FLOORS):
        print(f"floor: {line}")
    print(f"wrote {args.out / 'report.json'}")
    return report


if __name__ == "__main__":
    run_script(run, parse_args())
