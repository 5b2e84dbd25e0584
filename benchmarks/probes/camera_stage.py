"""The camera stage's cost per sample beside the render's, side by side in one run.

    python benchmarks/probes/camera_stage.py [--n 6] [--backends blender,mitsuba]

For each backend at 640x480 (default camera) and 1920x1200 (speedplus camera), renders samples 1..n
(sample 0 warms the renderer up) and prints the median time per sample of the whole render and of the
camera stage inside it (scgen.render.camera.record_image, timed where the backend calls it), and the
stage's share. Target: <= 5 % of a Blender 640x480 sample.

    python benchmarks/probes/camera_stage.py --stage-only --n 12 [--rounds 3] [--against REV] [--profile]

The stage alone, on one core (issue 79): renders n Mitsuba 640x480 samples of seed 0 (default camera),
keeps what the backend hands the stage (the spec, the linear composite, the instance map), then times
scgen.render.camera.record_image on each in a child process on one thread (OMP/BLAS/OpenCV at one
thread, one sample first as a warm-up); a sample's time is its fastest of the rounds, and it prints their
median. --against REV times the code of git revision REV too (a detached worktree, through PYTHONPATH),
the two children taking turns round by round (A B B A ...), then compares the 8-bit images sample by
sample (largest difference in DN, share of pixels that differ, PSNR). --profile adds cProfile's functions
by their own time for the working tree's code.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import pickle
import pstats
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
import numpy as np
from harness import ONE_THREAD, ROOT, parser, revision_tree, run_script

CASES = (("default", (640, 480)), ("speedplus", (1920, 1200)))


def timed(fn: Callable[..., Any], spent: list[float]) -> Callable[..., Any]:
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        spent.append(time.perf_counter() - t0)
        return out

    return wrapper


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--n", type=int, default=6, help="Samples timed per case, after a warm-up [6].")
    ap.add_argument("--backends", default="blender,mitsuba", help="[blender,mitsuba]")
    ap.add_argument("--quality", default="default", help="[default]")
    ap.add_argument("--stage-only", action="store_true", help="Time the stage alone on one core (see above).")
    ap.add_argument("--rounds", type=int, default=3, help="--stage-only: times each sample is timed [3].")
    ap.add_argument("--against", metavar="REV", help="--stage-only: also time git revision REV, compare.")
    ap.add_argument("--profile", action="store_true", help="--stage-only: cProfile's top functions.")
    ap.add_argument("--child", nargs=2, type=Path, help=argparse.SUPPRESS)  # inputs .pkl, output .npz
    return ap.parse_args()


def stage_inputs(n: int, quality: str, path: Path) -> None:
    """What Mitsuba hands the camera stage for samples 0..n-1 (seed 0, 640x480, default camera), pickled."""
    from scgen import Generator
    from scgen.render.mitsuba import backend as mitsuba_backend

    kept = []
    original = mitsuba_backend.record_image

    def keep(spec: Any, composite: np.ndarray, instance: np.ndarray) -> Any:
        kept.append((spec, np.array(composite), np.array(instance)))
        return original(spec, composite, instance)

    mitsuba_backend.record_image = keep
    try:
        with Generator.load(seed=0, resolution=(640, 480), backend="mitsuba", quality=quality) as gen:
            for i in range(n):
                gen.sample(i)
    finally:
        mitsuba_backend.record_image = original
    path.write_bytes(pickle.dumps(kept))


def stage_child(inputs: Path, out: Path, rounds: int, profile: bool) -> None:
    """Times record_image (the code PYTHONPATH imports) on each kept sample, on one thread."""
    import cv2

    cv2.setNumThreads(1)
    from scgen.render.camera import record_image

    kept = pickle.loads(inputs.read_bytes())
    record_image(*kept[0])  # caches
    prof = cProfile.Profile() if profile else None
    times, images = [], {}
    for i, sample in enumerate(kept):
        best = np.inf
        for _ in range(rounds):
            t0 = time.perf_counter()
            if prof:
                prof.enable()
            pixels, _ = record_image(*sample)
            if prof:
                prof.disable()
            best = min(best, time.perf_counter() - t0)
        times.append(best)
        images[f"img{i}"] = pixels
    if prof:
        text = io.StringIO()
        pstats.Stats(prof, stream=text).sort_stats("tottime").print_stats(16)
        print("\n".join(line for line in text.getvalue().splitlines()[4:] if line.strip()))
    np.savez(out, times=json.dumps(times), **images)


def stage_round(code: Path | None, inputs: Path, out: Path, rounds: int, profile: bool = False) -> dict:
    env = os.environ | ONE_THREAD | {"PYTHONPATH": str(code or ROOT)}
    cmd = [sys.executable, __file__, "--child", str(inputs), str(out), "--rounds", str(rounds)]
    subprocess.run(cmd + ["--profile"] * profile, env=env, check=True, cwd=code or ROOT)
    with np.load(out) as f:
        images = [f[f"img{i}"] for i in range(len(f.files) - 1)]
        return {"times": json.loads(str(f["times"])), "images": images}


def stage_only(args: argparse.Namespace) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        inputs = Path(tmp) / "inputs.pkl"
        stage_inputs(args.n, args.quality, inputs)
        print(f"load average {os.getloadavg()[0]:.2f}; {args.n} Mitsuba 640x480 samples of seed 0 (default"
              f" camera), one thread, fastest of {args.rounds} each; the stage's median ms")  # fmt: skip
        if not args.against:
            run = stage_round(None, inputs, Path(tmp) / "new.npz", args.rounds, args.profile)
            print(f"working  {1e3 * statistics.median(run['times']):8.1f}")
            return
        with revision_tree(args.against) as rev:
            runs: dict[str, list[float]] = {"old": [], "new": []}
            images = {}
            for r in range(2):  # A B B A
                for which in ("old", "new") if r == 0 else ("new", "old"):
                    code = rev / "code" if which == "old" else None
                    run = stage_round(code, inputs, Path(tmp) / f"{which}{r}.npz", args.rounds)
                    runs[which].append(run["times"])
                    images[which] = run["images"]
        old, new = ([min(t) for t in zip(*runs[w], strict=True)] for w in ("old", "new"))
        print(f"{args.against[:8]:8} {1e3 * statistics.median(old):8.1f}")
        ratio = statistics.median(new) / statistics.median(old)
        print(f"working  {1e3 * statistics.median(new):8.1f}  ({ratio:.3f} x)")
        print(f"load average {os.getloadavg()[0]:.2f}")
        print("images against REV: sample, largest |diff| DN, share of pixels differing, PSNR dB")
        for i, (a, b) in enumerate(zip(images["old"], images["new"], strict=True)):
            diff = np.abs(a.astype(np.int64) - b)
            mse = float(np.mean(diff.astype(np.float64) ** 2))
            peak = float(np.iinfo(a.dtype).max)
            psnr = np.inf if mse == 0 else 10 * np.log10(peak**2 / mse)
            print(f"  {i:3} {int(diff.max()):5} {float((diff > 0).mean()):9.2e} {psnr:8.2f}")
        if args.profile:
            stage_round(None, inputs, Path(tmp) / "profile.npz", 1, True)


def run(args: argparse.Namespace) -> None:
    if args.child:
        stage_child(*args.child, args.rounds, args.profile)
        return
    if args.stage_only:
        stage_only(args)
        return
    from scgen import Generator
    from scgen.render.blender import backend as blender
    from scgen.render.mitsuba import backend as mitsuba_backend

    n, backends, quality = args.n, args.backends, args.quality
    modules = {"blender": blender, "mitsuba": mitsuba_backend}
    print(f"{'backend':8} {'camera':10} {'size':>10} {'sample ms':>10} {'stage ms':>9} {'share':>6}")
    for backend in backends.split(","):
        module = modules[backend]
        for camera, resolution in CASES:
            stage: list[float] = []
            original = module.record_image
            module.record_image = timed(original, stage)
            try:
                with Generator.load(seed=1, resolution=resolution, camera=camera, backend=backend,
                                    quality=quality) as gen:  # fmt: skip
                    gen.sample(0)
                    totals = []
                    for i in range(1, n + 1):
                        t0 = time.perf_counter()
                        gen.sample(i)
                        totals.append(time.perf_counter() - t0)
            finally:
                module.record_image = original
            sample_ms, stage_ms = 1e3 * statistics.median(totals), 1e3 * statistics.median(stage[1:])
            size = f"{resolution[0]}x{resolution[1]}"
            print(f"{backend:8} {camera:10} {size:>10} {sample_ms:10.0f} {stage_ms:9.1f} "
                  f"{100 * stage_ms / sample_ms:5.1f}%")  # fmt: skip


if __name__ == "__main__":
    run_script(run, parse_args())
