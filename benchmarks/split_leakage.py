"""Factor-combination split vs image-level random split: combination leakage and split sizes.

Usage: python benchmarks/split_leakage.py [--n 1000 5000] [--seed 0]   (SceneSpecs only, no rendering)
"""

from __future__ import annotations

import argparse

from harness import parser, run_script

from scgen import Generator
from scgen.dataset.splits import SPLITS, leakage, plan_splits
from scgen.scenes import load_config
from scgen.scenes.factors import spec_key
from scgen.scenes.model import load_target


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--n", type=int, nargs="+", default=[1000, 5000])
    ap.add_argument("--seed", type=int, default=0)
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    cfg, model = load_config(), load_target()
    ratios = (0.7, 0.1, 0.2)
    head = f"{'n':>6} {'mode':<8} {'combos':>7} {'train/val/test %':>20} {'max dev pp':>10}"
    print(head + "  shared keys (tr-va, tr-te, va-te)")
    for n in args.n:
        generator = Generator(model, cfg, args.seed)
        keys = [spec_key(generator.scene(i)) for i in range(n)]
        for mode in ("factors", "random"):
            split_of = plan_splits(keys, ratios, args.seed, mode)
            shares = [100 * split_of.count(s) / n for s in SPLITS]
            dev = max(abs(s - 100 * r) for s, r in zip(shares, ratios, strict=True))
            leak = leakage(keys, split_of)
            print(f"{n:>6} {mode:<8} {len(set(keys)):>7} {'/'.join(f'{s:.1f}' for s in shares):>20} "
                  f"{dev:>10.2f}  {tuple(leak.values())}")  # fmt: skip


if __name__ == "__main__":
    run_script(run, parse_args())
