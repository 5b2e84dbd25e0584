"""Which data path and which step a run takes: `data.loader` and `optim.compile` set to `auto` decided
for the device it trains on, with the reason the start-up line gives.

The packed cache (`data.loader: cache`: the crop, background and colour applied to whole batches on the
device) and the compiled step (`optim.compile`: CUDA graphs) were built for a GPU, whose kernels idle
between eager mode's launches and whose loader processes cannot keep up with it; on a CPU the per-sample
loader and the eager step are the ones measured (docs/posenet.md). So `auto` takes the cache on CUDA
where the config allows it (the cache applies the paper's augmentations only), and the compiled step on
CUDA in one process (the compiled step is not built for DDP). An explicit value is taken as set.
"""

from __future__ import annotations

import dataclasses

import torch

from posenet.config import AUTO, TrainConfig


def resolve_fast_paths(cfg: TrainConfig, device: torch.device, world: int) -> tuple[TrainConfig, str]:
    """`cfg` with data.loader and optim.compile decided for `device` and `world` processes, and a line
    saying which path the run takes and why."""
    d, o = cfg.data, cfg.optim
    cuda = device.type == "cuda"
    loader, loader_why = d.loader, "as set"
    if d.loader == AUTO:
        if not cuda:
            loader, loader_why = "samples", "auto: not on CUDA"
        elif d.augment != "paper" or d.truncate_fg:
            loader, loader_why = "samples", "auto: the cache applies the paper's augmentations only"
        else:
            loader, loader_why = "cache", "auto: on CUDA"
    compiled, compile_why = o.compile, "as set"
    if o.compile == AUTO:
        compiled = cuda and world == 1
        compile_why = "auto: " + ("on CUDA in one process" if compiled else "not on CUDA" if not cuda else
                                  f"{world} DDP processes")  # fmt: skip
    resolved = dataclasses.replace(
        cfg,
        data=dataclasses.replace(d, loader=loader),
        optim=dataclasses.replace(o, compile=bool(compiled)),
    )
    step = "compiled" if compiled else "eager"
    return resolved, f"paths: data.loader {loader} ({loader_why}), step {step} (optim.compile {compile_why})"
