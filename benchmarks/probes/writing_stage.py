"""What writing a sample costs (scgen.dataset.writer.write_sample: encoding, scene_gt_info, the record), on
one core (issue 79).

    python benchmarks/probes/writing_stage.py [--n 8] [--rounds 5] [--against REV]

A child process on one thread (OMP/BLAS/OpenCV at one thread) renders n 640x480 samples of seed 4 with
Mitsuba (the default camera: JPEG images), then writes each of them `rounds` times into fresh dataset
folders; a sample's time is its fastest write, and the child prints the median over the samples in ms.
--against REV runs the code of git revision REV too (a detached worktree on the child's PYTHONPATH), the
two children taking turns (A B B A), and prints both medians and their ratio.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import ONE_THREAD, ROOT, parser, revision_tree, run_script


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--n", type=int, default=8, help="Samples [8].")
    ap.add_argument("--rounds", type=int, default=5, help="Writes of each sample; the fastest counts [5].")
    ap.add_argument("--against", metavar="REV", help="Also time git revision REV.")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    return ap.parse_args()


def child(n: int, rounds: int) -> None:
    """Render n samples, time their writes; print the median fastest write in ms."""
    import cv2

    from scgen.dataset.layout import Layout
    from scgen.dataset.writer import WriteOptions, write_sample
    from scgen.generator import Generator
    from scgen.run.runner import write_static_files

    cv2.setNumThreads(1)
    generator = Generator.load(seed=4, resolution=(640, 480), backend="mitsuba", threads=1)
    samples = [generator.sample(i) for i in range(n)]
    best = [float("inf")] * n
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(rounds):
            layout = Layout(Path(tmp) / f"r{r}")
            write_static_files(layout, generator)
            for k, s in enumerate(samples):
                t = time.perf_counter()
                write_sample(layout, s.spec, s.buffers, s.annotation, "train", WriteOptions(rgb_format="jpg"))
                best[k] = min(best[k], time.perf_counter() - t)
    print(f"{1000 * statistics.median(best):.2f}")


def timed(code: Path, args: argparse.Namespace) -> float:
    """The child's median write in ms, with the scgen package found in `code`."""
    env = {**os.environ, **ONE_THREAD, "PYTHONPATH": str(code)}
    argv = [sys.executable, __file__, "--child", "--n", str(args.n), "--rounds", str(args.rounds)]
    out = subprocess.run(argv, env=env, check=True, capture_output=True, text=True).stdout
    return float(out.split()[-1])


def run(args: argparse.Namespace) -> None:
    if args.child:
        child(args.n, args.rounds)
        return
    if args.against is None:
        print(f"writing: {timed(ROOT, args):.2f} ms a sample (median of {args.n}, fastest of {args.rounds})")
        return
    with revision_tree(args.against) as tmp:
        old = tmp / "code"
        times: dict[str, list[float]] = {"this tree": [], args.against: []}
        order = ((ROOT, "this tree"), (old, args.against), (old, args.against), (ROOT, "this tree"))
        for code, name in order:
            times[name].append(timed(code, args))
    medians = {name: statistics.median(v) for name, v in times.items()}
    for name, value in medians.items():
        print(f"{name:>12s}: {value:.2f} ms a sample (runs {', '.join(f'{v:.2f}' for v in times[name])})")
    print(f"ratio {args.against} / this tree: {medians[args.against] / medians['this tree']:.2f}")


if __name__ == "__main__":
    run_script(run, parse_args())
