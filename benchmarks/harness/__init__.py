"""What every script under benchmarks/ shares, so that no script imports another (benchmarks/MANIFEST.toml
lists the scripts):

- running: `parser` (the script's docstring as its --help; a bad option is one `Error:` line; with
  `render_figure_args`, a rendered picture's --backend, --quality and --out) and
  `run_script` (bad input, an unreadable or unwritable file, a failed child command: one `Error: ...` line
  and exit status 1, through the shell of the scgen and posenet command lines, clishell);
- seeds: the learning benchmark's dataset, which the pose benchmarks render alike (SEED, RENDER_N, ...);
- --out: `fresh_run` (a run folder that holds a run is refused, or deleted with --overwrite);
- tables and plots: `pct`, `pyplot`, `label` (a caption on a picture's panel);
- image quality: `foreground_psnr` (a render against a reference, over the objects);
- `revision_tree`: the code at another git revision, for the before/after comparisons.

It imports neither torch nor a renderer, so every script's --help stays quick, and of the project only
clishell and posenet's error type, so that a child process running another revision's scgen (the
before/after figure's) imports it too. The scripts of benchmarks/figures/ and benchmarks/probes/ put
benchmarks/ on sys.path to import it. The posenet
training runs that several scripts share, and their resuming, live in `harness.pose`.
"""

from __future__ import annotations

import argparse
import math
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NoReturn

from clishell.errors import UserError
from clishell.group import exit_with
from posenet.errors import PosenetError

ROOT = Path(__file__).resolve().parents[2]  # the repository
# a child process timed on one core: its BLAS and OpenMP at one thread (the probes of a stage's cost)
ONE_THREAD = {k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
# the learning benchmark's dataset (benchmarks/figures/posenet_learning.py), which the pose benchmarks share:
# 1000 samples of seed 7 at 320x240 through Mitsuba, 2 render workers
RENDER_N, SEED, RESOLUTION, BACKEND, WORKERS = 1000, 7, (320, 240), "mitsuba", 2


class Parser(argparse.ArgumentParser):
    """argparse whose usage errors end as the CLIs' do: the usage, then one `Error: ...` line (exit 2)."""

    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        self.exit(2, f"Error: {message}\n")


def foreground_psnr(rgb: Any, ref: Any, instance: Any) -> float:
    """PSNR (dB) of an 8-bit sRGB image against a reference over the rendered objects (instance > 0),
    dilated by 2 px to include their edges: how a render setting is scored against a many-spp reference."""
    import cv2
    import numpy as np

    region = cv2.dilate((instance > 0).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    err = (rgb.astype(np.float64) - ref.astype(np.float64))[region]
    return float(10 * np.log10(255.0**2 / max(1e-12, float(np.mean(err**2)))))


def parser(doc: str | None) -> Parser:
    """A script's parser: its module docstring, as written, is its --help."""
    return Parser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)


def render_figure_args(doc: str | None, picture: str) -> argparse.Namespace:
    """The arguments of a script that renders docs/`picture`: --backend (Mitsuba by default: the fast CPU
    renderer), --quality and --out."""
    ap = parser(doc)
    ap.add_argument("--backend", default="mitsuba", help="[mitsuba]")
    ap.add_argument("--quality", default="default", help="[default]")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / picture, help=f"[docs/{picture}]")
    return ap.parse_args()


def run_script(run: Callable[[argparse.Namespace], object], args: argparse.Namespace) -> None:
    """Run a script's work: a user error (clishell.UserError: ScgenError, PosenetError), an OSError or a
    failed child command ends it with one `Error: ...` line on stderr and exit status 1, through the
    command lines' own shell (clishell.group.exit_with); anything else is a bug and keeps its traceback."""
    try:
        run(args)
    except (UserError, OSError) as exc:
        exit_with(exc)
    except subprocess.CalledProcessError as exc:
        command = " ".join(map(str, exc.cmd)) if isinstance(exc.cmd, list | tuple) else str(exc.cmd)
        exit_with(UserError(f"{command} exited with status {exc.returncode}"))


def positive(text: str) -> int:
    """An argparse type: an integer >= 1."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def parse_resolution(text: str) -> tuple[int, int]:
    """An argparse type: WxH, two positive integers."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"resolution must look like 320x240, got {text!r}") from None
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"resolution must be positive, got {text!r}")
    return w, h


def fresh_run(run_dir: Path, overwrite: bool) -> None:
    """--out: a run folder that holds a run (its last.pt) is refused, or with --overwrite deleted."""
    if (run_dir / "last.pt").exists():
        if not overwrite:
            raise PosenetError(f"{run_dir} already holds a run; pass --overwrite or choose another --out")
        shutil.rmtree(run_dir)


def pct(v: float | None) -> str:
    """A share as a percentage for tables; '-' for none."""
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{100 * v:.2f}"


def pyplot() -> Any:
    """matplotlib's pyplot on the file-only Agg backend (imported on first use: it is slow to import)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


@contextmanager
def revision_tree(rev: str) -> Iterator[Path]:
    """A temporary folder holding `tmp/code`, the tree at git revision `rev` (a detached worktree, removed on
    exit), for a child process to import scgen from (PYTHONPATH)."""
    with tempfile.TemporaryDirectory() as tmp:
        code = Path(tmp) / "code"
        subprocess.run(["git", "worktree", "add", "--detach", "-q", str(code), rev], cwd=ROOT, check=True)
        try:
            yield Path(tmp)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(code)], cwd=ROOT, check=True)


def label(image: Any, text: str) -> Any:
    """A copy of an RGB panel (uint8) with `text` written in its top-left corner, white on a black outline."""
    import cv2  # only the picture scripts need it

    out = image.copy()
    cv2.putText(out, text, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(out, text, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1, cv2.LINE_AA)
    return out
