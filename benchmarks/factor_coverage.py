"""Factor coverage of the default sampling config, and mean target luminance per illumination level.

Usage: python benchmarks/factor_coverage.py [--n 400] [--seed 0] [--lum-n 150] [--plan-n 0]

Coverage: n SceneSpecs sampled exactly as `scgen render` samples them (default config, 640x480),
rendered by the Mitsuba backend's geometry-only path (MitsubaBackend.render_geometry: the exact
ray-cast passes of a real render, RGB skipped), then labelled by the same scgen.annotate.annotate()
as every dataset: so shadow and occlusion groups are the measured labels, not the sampler's intent.
The table marks groups under 15 % (30 % for the two shadow labels) with '*'.

Luminance: lum-n samples fully rendered (Mitsuba, 320x240, draft); per image the mean linear
luminance of the visible target pixels (scgen.render.lighting.mean_luminance); per level the
quartiles, and whether the three interquartile ranges are disjoint.

Plan (--plan-n N, e.g. 50000): the groups fixed when a scene is sampled, counted over N SceneSpecs
without rendering: illumination, background, finish, and the flare candidates (the sun within the lens'
flare reach of the field of view; the rendered label is "no" only where objects hide the whole disc).
"""

from __future__ import annotations

import argparse
import time
from collections import Counter

import numpy as np
from harness import parser, run_script

from scgen import Generator
from scgen.annotate import annotate
from scgen.render.camera.glare import FLARE_REACH_RAD, sun_view
from scgen.render.lighting import mean_luminance
from scgen.render.mitsuba.backend import MitsubaBackend
from scgen.scenes.factors import FACTOR_GROUPS, distance_groups
from scgen.scenes.finish import finish_group

MIN_SHARE = {"shadow": 0.30}  # every other factor: 0.15


def coverage(n: int, seed: int) -> None:
    generator = Generator.load(seed=seed)
    model, cfg = generator.model, generator.cfg
    t0 = time.perf_counter()
    specs = [generator.scene(i) for i in range(n)]
    t_sample = (time.perf_counter() - t0) / n
    backend = MitsubaBackend(model, quality="draft")
    t0 = time.perf_counter()
    anns = [annotate(s, backend.render_geometry(s)) for s in specs]
    t_geo = (time.perf_counter() - t0) / n
    labels = {
        "illumination": [s.sun.level for s in specs],
        "shadow": [a.shadow_label for a in anns],
        "occlusion": [a.occlusion_group for a in anns],
        "background": [s.background.kind for s in specs],
        "distance": distance_groups(np.array([s.distance_m for s in specs]))[0],
    }
    size = f"{cfg['camera']['width']}x{cfg['camera']['height']}"
    print(f"{n} samples, seed {seed}, {size}: sampling {1000 * t_sample:.1f} ms/spec, "
          f"geometry render + annotate {t_geo:.2f} s/sample")  # fmt: skip
    print(f"{'factor':<13}{'group':<10}{'count':>6}{'share':>8}")
    for factor, groups in FACTOR_GROUPS.items():
        counts = Counter(labels[factor])
        for k, group in enumerate(groups):
            share = counts[group] / n
            mark = "*" if share < MIN_SHARE.get(factor, 0.15) else ""
            print(f"{factor if k == 0 else '':<13}{group:<10}{counts[group]:>6}{100 * share:>7.1f}%{mark}")
    print("\nrequested occlusion -> measured group (rows: requested)")
    groups = FACTOR_GROUPS["occlusion"]
    print(f"{'':<10}" + "".join(f"{g:>10}" for g in groups))
    pairs = list(zip(specs, anns, strict=True))
    for req in groups:
        row = Counter(a.occlusion_group for s, a in pairs if s.requested_occlusion == req)
        print(f"{req:<10}" + "".join(f"{row[g]:>10}" for g in groups))
    for caster in (True, False):
        sel = [a.shadow_label for s, a in pairs if s.shadow_caster == caster]
        print(f"caster sampled={caster}: {len(sel)} samples, shadow label yes {sel.count('yes')}")


def luminance(n: int, seed: int) -> None:
    generator = Generator.load(seed=seed, resolution=(320, 240), backend="mitsuba", quality="draft")
    cfg = generator.cfg
    per_level: dict[str, list[float]] = {level: [] for level in FACTOR_GROUPS["illumination"]}
    for i in range(n):
        sample = generator.sample(i)
        ann = sample.annotation
        if ann.px_count_visib >= 20:  # a few pixels say nothing about brightness
            per_level[sample.spec.sun.level].append(mean_luminance(sample.buffers.rgb, ann.mask_visib))
    mult = cfg["illumination"]["multipliers"]
    print(f"\nmean target luminance (linear, 1 = white) per level, {n} samples at 320x240, "
          f"exposure EV {cfg['camera']['exposure_ev']:+.1f}")  # fmt: skip
    print(f"{'level':<8}{'x sun':>7}{'n':>5}{'p10':>8}{'p25':>8}{'median':>8}{'p75':>8}{'p90':>8}")
    iqr = []
    for level, values in per_level.items():
        p = np.percentile(values, [10, 25, 50, 75, 90])
        iqr.append((p[1], p[3]))
        print(f"{level:<8}{mult[level]:>7.2f}{len(values):>5}" + "".join(f"{x:>8.3f}" for x in p))
    disjoint = all(iqr[k][1] < iqr[k + 1][0] for k in range(len(iqr) - 1))
    print(f"interquartile ranges disjoint and ordered: {disjoint}")


def plan(n: int, seed: int) -> None:
    generator = Generator.load(seed=seed)
    counts: dict[str, Counter] = {f: Counter() for f in ("illumination", "background", "flare", "finish")}
    t0 = time.perf_counter()
    for i in range(n):
        spec = generator.scene(i)
        view = sun_view(spec.camera, np.asarray(spec.sun.direction))
        near = view is not None and view.off_view_rad <= FLARE_REACH_RAD
        counts["illumination"][spec.sun.level] += 1
        counts["background"][spec.background.kind] += 1
        counts["flare"][FACTOR_GROUPS["flare"][int(near)]] += 1
        counts["finish"][finish_group(spec.finish)] += 1
    print(f"\nplan of {n} samples, seed {seed}: {time.perf_counter() - t0:.0f} s")
    for factor, counter in counts.items():
        print(f"{factor:<13}" + ", ".join(f"{g} {counter[g]}" for g in FACTOR_GROUPS[factor]))


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--n", type=int, default=400)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--lum-n", type=int, default=150)
    ap.add_argument("--plan-n", type=int, default=0, help="Count the planned groups of this many samples.")
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    if args.n:
        coverage(args.n, args.seed)
    if args.lum_n:
        luminance(args.lum_n, args.seed)
    if args.plan_n:
        plan(args.plan_n, args.seed)


if __name__ == "__main__":
    run_script(run, parse_args())
