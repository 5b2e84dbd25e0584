"""The full count: `scgen render --n 50000 --split-by factors` end to end, then `scgen stats`,
`scgen validate` and posenet's dataset indexing, at a small image size so it fits one machine.

It is the plan, splits, writer, finalize, stats and validate of a full-size run with fewer pixels.
Prints, and writes to OUT/full_count.json (with the RSS trace in OUT/full_count_rss.csv):
- the wall time of each phase (plan, render, finalize, stats, validate, indexing);
- peak RSS of the main process and of the largest worker per phase, and both over the render in
  tenths of its time (flat means no per-sample growth);
- bytes per sample on disk, by file kind;
- a cost model for the same count with Blender at 640x480 on 2, 16 and 64 cores (see cost_model): the
  per-sample render core-seconds (--blender-core-s, from benchmarks/bench_workers.py) and validate's
  (measured on --full-size-n samples at 640x480) spread over the cores, plus this run's plan, finalize,
  stats and indexing.

A run interrupted by anything resumes with the same command (render skips complete samples).

Usage: python benchmarks/full_count.py --out DIR [--n 50000] [--backend mitsuba] [--resolution 64x48]
       [--workers 2] [--seed 0] [--blender-core-s 2.64]
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import json
import threading
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import psutil
from harness import parser, run_script

from posenet.config import load_config
from posenet.data import open_split
from scgen.dataset.layout import bytes_by_kind
from scgen.dataset.splits import SPLITS
from scgen.dataset.stats import compute_stats, format_table
from scgen.dataset.validate import validate_dataset
from scgen.run.runner import RenderJob, run_render

MB = 1024 * 1024
FULL_SIZE = (640, 480)  # the cost model's image size
# 2 workers x 1 thread at 640x480, default quality, a box per object traced: 0.759 img/s steady
# (docs/scale-out.md, bench_workers.py --backend blender --n 24 --runs 2x1 --repeat 2, 2026-11-28)
BLENDER_CORE_S = 2 / 0.759


class RssTrace(threading.Thread):
    """Samples the RSS of this process and of each child process once a second, tagged by phase."""

    def __init__(self, period_s: float = 1.0) -> None:
        super().__init__(daemon=True)
        self.period_s = period_s
        self.phase = "start"
        self.rows: list[tuple[float, str, float, float]] = []  # (t, phase, main MB, largest child MB)
        self._halt = threading.Event()
        self._me = psutil.Process()
        self._t0 = time.perf_counter()

    def run(self) -> None:
        while not self._halt.wait(self.period_s):
            child = 0
            for c in self._me.children(recursive=True):
                with contextlib.suppress(psutil.NoSuchProcess):
                    child = max(child, c.memory_info().rss)
            main_mb = self._me.memory_info().rss / MB
            self.rows.append((time.perf_counter() - self._t0, self.phase, main_mb, child / MB))

    def stop(self) -> None:
        self._halt.set()
        self.join()

    def peaks(self) -> dict[str, dict[str, float]]:
        out: dict[str, dict[str, float]] = defaultdict(lambda: {"main_mb": 0.0, "worker_mb": 0.0})
        for _, phase, main, child in self.rows:
            out[phase]["main_mb"] = max(out[phase]["main_mb"], main)
            out[phase]["worker_mb"] = max(out[phase]["worker_mb"], child)
        return dict(out)

    def tenths(self, phase: str) -> list[tuple[float, float]]:
        """(main MB, worker MB) peaks in each tenth of the phase's samples, in time order."""
        rows = [r for r in self.rows if r[1] == phase]
        if len(rows) < 10:
            return []
        step = len(rows) / 10
        parts = [rows[int(k * step) : int((k + 1) * step)] for k in range(10)]
        return [(max(r[2] for r in p), max(r[3] for r in p)) for p in parts]

    def write_csv(self, path: Path) -> None:
        with path.open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["t_s", "phase", "main_rss_mb", "largest_worker_rss_mb"])
            w.writerows((f"{t:.1f}", p, f"{m:.1f}", f"{c:.1f}") for t, p, m, c in self.rows)


def timed(trace: RssTrace, phase: str, fn: Callable[[], Any]) -> tuple[float, Any]:
    trace.phase = phase
    t0 = time.perf_counter()
    result = fn()
    return time.perf_counter() - t0, result


def index_splits(root: Path) -> dict[str, int]:
    """posenet train's dataset indexing (open_split) of every split; instances per split."""
    cfg = load_config("paper")
    return {s: len(open_split(root, s, cfg.data, cfg.model_config(), train=s == "train")) for s in SPLITS}


def full_size_validate_s(out: Path, n: int, seed: int) -> float:
    """Seconds of one core per sample that validate spends on 640x480 samples (n Mitsuba samples, draft
    quality, rendered into OUT/full_size): the checks read every pixel, so the cost model uses this."""
    data = out / "full_size"
    job = RenderJob(
        out=data, n=n, seed=seed, backend="mitsuba", quality="draft", resolution=FULL_SIZE, workers=2
    )
    run_render(job, progress=False)
    t0 = time.perf_counter()
    validate_dataset(data, progress=False, workers=1)
    return (time.perf_counter() - t0) / n


def cost_model(phases: dict[str, float], n: int, workers: int, validate_core_s: float,
               blender_core_s: float) -> list[dict[str, Any]]:  # fmt: skip
    """Hours for n Blender samples at 640x480 on 2, 16 and 64 cores. Render and validate: core-seconds
    per sample (blender_core_s, validate_core_s) spread over the cores; plan: this run's time on its
    `workers`, spread over the cores (it samples every SceneSpec in parallel); finalize, stats and
    indexing: this run's times, on one core (they read JSON and CSV, not pixels)."""
    serial_s = phases["finalize"] + phases["stats"] + phases["indexing"]
    rows = []
    for cores in (2, 16, 64):
        render_h = n * blender_core_s / cores / 3600
        other_h = (phases["plan"] * workers / cores + n * validate_core_s / cores + serial_s) / 3600
        rows.append({"cores": cores, "render_h": render_h, "other_h": other_h, "total_h": render_h + other_h})
    return rows


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--n", type=int, default=50000)
    ap.add_argument("--backend", default="mitsuba")
    ap.add_argument("--resolution", default="64x48")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--full-size-n", type=int, default=24, help="640x480 samples to time validate on [24]")
    ap.add_argument(
        "--blender-core-s",
        type=float,
        default=BLENDER_CORE_S,
        help="Blender core-seconds per 640x480 sample for the cost model [%(default).2f]",
    )
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    w, h = (int(v) for v in args.resolution.lower().split("x"))
    data = args.out / "dataset"
    job = RenderJob(
        out=data,
        n=args.n,
        seed=args.seed,
        backend=args.backend,
        resolution=(w, h),
        split_by="factors",
        workers=args.workers,
    )
    trace = RssTrace()
    trace.start()
    trace.phase = "render"  # run_render's own plan/render/finalize split is in its summary
    summary = run_render(job, progress=True)
    stats_s, stats = timed(trace, "stats", lambda: compute_stats(data))
    validate_s, (problems, checked) = timed(
        trace, "validate", lambda: validate_dataset(data, workers=args.workers)
    )
    index_s, instances = timed(trace, "indexing", lambda: index_splits(data))
    trace.phase = "640x480 validate timing"
    validate_core_s = full_size_validate_s(args.out, args.full_size_n, args.seed)
    trace.stop()
    trace.write_csv(args.out / "full_count_rss.csv")

    phases = {
        "plan": summary["plan_s"],
        "render": summary["render_wall_s"],
        "finalize": summary["finalize_s"],
        "stats": stats_s,
        "validate": validate_s,
        "indexing": index_s,
    }
    kinds = bytes_by_kind(data)
    report = {
        "n": args.n,
        "backend": args.backend,
        "resolution": [w, h],
        "workers": args.workers,
        "rendered": summary["rendered"],
        "skipped": summary["skipped"],
        "splits": summary["splits"],
        "phases_s": phases,
        "render_img_per_s": summary["rendered"] / max(summary["render_wall_s"], 1e-9),
        "rss_peak_mb": trace.peaks(),
        "render_rss_tenths_mb": trace.tenths("render"),
        "bytes_per_sample": {k: v / args.n for k, v in kinds.items()},
        "bytes_per_sample_total": sum(kinds.values()) / args.n,
        "validate": {"samples": checked, "problems": len(problems), "first": problems[:5]},
        "instances": instances,
        "validate_core_s_640x480": validate_core_s,
        "cost_model_blender_640x480": cost_model(
            phases, args.n, args.workers, validate_core_s, args.blender_core_s
        ),
    }
    (args.out / "full_count.json").write_text(json.dumps(report, indent=1))

    print(format_table(stats))
    print(
        f"\n{args.n} samples, {args.backend} {w}x{h}, {args.workers} workers "
        f"(rendered {summary['rendered']}, resumed past {summary['skipped']}); splits {summary['splits']}"
    )
    print("phase wall times: " + ", ".join(f"{k} {v:.1f} s" for k, v in phases.items()))
    print(
        "peak RSS (main / largest worker, MB; render includes plan and finalize): "
        + ", ".join(f"{k} {v['main_mb']:.0f}/{v['worker_mb']:.0f}" for k, v in report["rss_peak_mb"].items())
    )
    print(f"render: {report['render_img_per_s']:.2f} img/s")
    print(
        "RSS over the render, by tenth (main / largest worker, MB): "
        + "  ".join(f"{m:.0f}/{c:.0f}" for m, c in report["render_rss_tenths_mb"])
    )
    print(
        f"bytes per sample: {report['bytes_per_sample_total'] / 1024:.1f} KiB ("
        + ", ".join(f"{k} {v / 1024:.1f}" for k, v in sorted(report["bytes_per_sample"].items()))
        + ")"
    )
    print(f"validate: {checked} samples, {len(problems)} problem(s); indexing: {instances}")
    print(
        f"cost model, {args.n} Blender samples at 640x480 ({args.blender_core_s:.2f} core-s each to render, "
        f"{1000 * validate_core_s:.0f} core-ms to validate):"
    )
    for r in report["cost_model_blender_640x480"]:
        print(
            f"  {r['cores']:>3} cores: render {r['render_h']:.1f} h + the rest {r['other_h']:.2f} h"
            f" = {r['total_h']:.1f} h"
        )


if __name__ == "__main__":
    run_script(run, parse_args())
