"""Mitsuba's path length against a 512-spp reference (issue 79, item 2): time and image per max_depth.

Cycles' bounces were measured this way (bench_blender.py --settings-frames); this is the Mitsuba
backend's counterpart. Each max_depth (scgen.render.mitsuba.backend.PATH_MAX_DEPTH, the default 4: the
sun's direct light and two bounces) renders on a backend of its own, one renderer thread, the default
quality (16 spp) through the window, after --warmup samples that record its windows; then --n scenes of
seed 0 at 640x480 are timed and scored: PSNR of the recorded 8-bit image over the objects (dilated 2 px)
against the same scene at 512 spp, max_depth 8, the whole frame (the camera stage's noise is the same
draw in both). The depths run in turn, --rounds times, the fastest time per depth kept.

Usage: python benchmarks/probes/mitsuba_depth.py [--n 12] [--warmup 24] [--depths 4 3 2] [--rounds 2]
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import foreground_psnr, parser, run_script

import scgen.render.mitsuba.backend as mitsuba_backend
from scgen import Generator
from scgen.scenes import load_config
from scgen.scenes.model import load_target

REF_SPP, REF_DEPTH = 512, 8


def backend_at(model, spp: int | None = None, region: bool = True, threads: int = 1):
    """A Mitsuba backend at `spp` samples a pixel (None: the default quality's)."""
    backend = mitsuba_backend.MitsubaBackend(model, threads=threads, region=region)
    if spp:
        backend.spp = spp
    return backend


def render_at(backend, depth: int, specs: list) -> list:
    """The backend's renders of `specs`, any scene it builds meanwhile stopping its paths at `depth`: a
    backend builds a scene per camera and set of lights on first need, from PATH_MAX_DEPTH as it is then."""
    mitsuba_backend.PATH_MAX_DEPTH = depth
    return [backend.render(spec) for spec in specs]


def run(args) -> None:
    model = load_target()
    generator = Generator(model, load_config(resolution=(640, 480)), 0)
    scored = [generator.scene(i) for i in range(args.n)]
    warmup = [generator.scene(i) for i in range(args.n, args.n + args.warmup)]
    refs = render_at(backend_at(model, REF_SPP, region=False, threads=2), REF_DEPTH, scored)
    backends = {}
    for depth in args.depths:
        backends[depth] = backend_at(model)
        render_at(backends[depth], depth, warmup)
    times = {d: [] for d in args.depths}
    psnrs = {d: [] for d in args.depths}
    for _ in range(args.rounds):
        for depth, backend in backends.items():
            mitsuba_backend.dr.set_thread_count(1)
            t0 = time.perf_counter()
            out = render_at(backend, depth, scored)
            times[depth].append((time.perf_counter() - t0) / len(scored))
            psnrs[depth] = [foreground_psnr(b.rgb, r.rgb, r.instance) for b, r in zip(out, refs, strict=True)]
    print(f"Mitsuba max_depth, {args.n} scenes of seed 0 at 640x480, 16 spp through the window, one thread, "
          f"vs {REF_SPP} spp at max_depth {REF_DEPTH} (fastest of {args.rounds} rounds):")  # fmt: skip
    print(f"  {'max_depth':>9s} {'s/sample':>9s} {'PSNR dB':>8s}")
    for depth in args.depths:
        print(f"  {depth:9d} {min(times[depth]):9.3f} {statistics.mean(psnrs[depth]):8.2f}")


if __name__ == "__main__":
    ap = parser(__doc__)
    ap.add_argument("--n", type=int, default=12, help="scenes timed and scored")
    ap.add_argument("--warmup", type=int, default=24, help="samples each backend renders first")
    ap.add_argument("--depths", type=int, nargs="+", default=[4, 3, 2])
    ap.add_argument("--rounds", type=int, default=2)
    run_script(run, ap.parse_args())
