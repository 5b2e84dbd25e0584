"""Mitsuba backend throughput, time outside the renderer, bytes per sample by file kind, and the
float16-vs-float32 xyz storage error. Usage: python benchmarks/bench_mitsuba.py [--n 30] [--out DIR]"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import trimesh

from scgen.annotate import annotate
from scgen.dataset import Layout
from scgen.factors import spec_key
from scgen.generator import Generator
from scgen.model import load_target
from scgen.render.base import create_backend
from scgen.runner import write_static_files
from scgen.scenes import load_config
from scgen.splits import plan_splits
from scgen.validate import reprojection_error
from scgen.writer import WriteOptions, finalize, write_sample


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=30)
    ap.add_argument("--quality", default="default")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    out = args.out or Path(tempfile.mkdtemp()) / "bench"
    model, cfg = load_target(), load_config()
    backend = create_backend("mitsuba", model, quality=args.quality)
    generator = Generator(model, cfg, 0)
    specs = [generator.scene(i) for i in range(args.n)]
    splits = plan_splits([spec_key(s) for s in specs], (0.7, 0.1, 0.2), 0)
    layout = Layout(out)
    write_static_files(layout, generator)
    surface = trimesh.proximity.ProximityQuery(model.mesh)
    backend.render(specs[0])  # warm-up (JIT compilation)
    t_render = t_other = 0.0
    errors: dict[str, list[np.ndarray]] = defaultdict(list)
    for spec, split in zip(specs, splits, strict=True):
        t0 = time.perf_counter()
        buffers = backend.render(spec)
        t1 = time.perf_counter()
        ann = annotate(spec, buffers)
        write_sample(layout, spec, buffers, ann, split, WriteOptions())
        t2 = time.perf_counter()
        t_render += t1 - t0
        t_other += t2 - t1
        vs, us = np.nonzero(ann.mask_visib)
        for dtype in ("float16", "float32"):
            C = ann.xyz[vs, us].astype(dtype).astype(np.float64)
            errors[f"{dtype} reproj px"].append(
                reprojection_error(C, us, vs, spec.camera.K_mat, spec.target.R_mat, spec.target.t_vec)
            )
            errors[f"{dtype} surface mm"].append(surface.on_surface(C)[1] * 1000)
    finalize(layout)
    total = t_render + t_other
    print(f"Mitsuba ({backend.variant}, {args.quality}, 640x480), {args.n} samples")
    print(f"  images/s: {args.n / total:.2f}   render {t_render / args.n:.3f} s/img")
    print(f"  time outside the renderer (annotation + writing): {100 * t_other / total:.1f} %")
    sizes: dict[str, int] = defaultdict(int)
    static = 0  # written once per dataset: models, models_eval, camera, config, test targets
    for p in out.rglob("*"):
        if not p.is_file():
            continue
        if p.parent == out or p.relative_to(out).parts[0] in ("models", "models_eval"):
            static += p.stat().st_size
            continue
        kinds = ("rgb", "depth", "mask", "mask_visib", "xyz", "records")
        sizes[p.parent.name if p.parent.name in kinds else "json/meta"] += p.stat().st_size
    print(f"  files written once per dataset: {static / 2**20:.1f} MB")
    print("  bytes per sample by file kind:")
    for kind, b in sorted(sizes.items()):
        print(f"    {kind:<11s} {b / args.n / 1024:8.1f} KB")
    per = sum(sizes.values()) / args.n
    print(f"    {'total':<11s} {per / 1024:8.1f} KB  -> 50k samples: {per * 50000 / 1e9:.1f} GB")
    print("  xyz storage error (all visible pixels): p99 / max")
    for name, vals in errors.items():
        v = np.concatenate(vals)
        print(f"    {name:<18s} {np.percentile(v, 99):.4f} / {v.max():.4f}")


if __name__ == "__main__":
    main()
