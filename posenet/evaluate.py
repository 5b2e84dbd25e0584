"""Evaluation: pose errors, ADD/ADD-S recalls, ESA score and batch-1 latency of a checkpoint on a split.

`evaluate` returns the summary and one record per instance; `by_factor` gives the paper's Table 5:
ADD@0.02 m per (factor, group) over fixed sample lists, one column per variant, checkpoints of the same
variant averaged.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import DataLoader

from posenet.checkpoint import load_checkpoint
from posenet.config import config_from_dict
from posenet.data import open_split
from posenet.errors import PosenetError
from posenet.geometry import decode_pose
from posenet.metrics import sample_errors, summarise
from posenet.models import ModelConfig, PoseNet, build_model

WARMUP_IMAGES = 5  # excluded from the latency mean (allocator, cuDNN autotuning)


@dataclass
class EvalResult:
    variant: str
    summary: dict[str, float]  # see metrics.summarise, plus latency_ms and fps
    records: list[dict[str, Any]]  # one per instance: ids, predicted pose, errors


def load_model(ckpt: Path, device: torch.device) -> tuple[PoseNet, dict[str, Any]]:
    """The network of a checkpoint, in eval mode on `device`, and the checkpoint itself."""
    state = load_checkpoint(ckpt)
    model_cfg = ModelConfig.from_dict(state["model_config"])
    model = build_model(state["model_config"]["variant"], model_cfg)
    try:
        model.load_state_dict(state["model"])
    except RuntimeError as exc:
        raise PosenetError(f"checkpoint {ckpt} does not match its own model configuration") from exc
    return model.to(device).eval(), state


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def evaluate(
    data: Path,
    ckpt: Path,
    split: str = "test",
    boxes: Path | None = None,
    image_ids: set[int] | None = None,
    workers: int = 2,
) -> EvalResult:
    """Run the checkpoint over the split at batch 1 on the current device (GPU if any)."""
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    model, state = load_model(ckpt, device)
    cfg = config_from_dict(state["config"])
    dataset = open_split(
        data, split, cfg.data, model.config, train=False, boxes_file=boxes, image_ids=image_ids
    )
    points = torch.from_numpy(dataset.obj.pm_points).to(device)  # uniform surface points, as the PM loss
    loader = DataLoader(dataset, batch_size=1, num_workers=workers)
    errors: dict[str, list[float]] = {}
    records, times = [], []
    with torch.inference_mode():
        for batch in loader:
            b = {k: v.to(device) for k, v in batch.items()}
            _sync(device)
            tic = time.perf_counter()
            R, t = decode_pose(model(b["roi_img"], b["roi_coord2d"]), b)
            _sync(device)
            times.append(time.perf_counter() - tic)
            errs = {k: float(v[0]) for k, v in sample_errors(R, t, b["R"], b["t"], points).items()}
            for k, v in errs.items():
                errors.setdefault(k, []).append(v)
            scene_id, im_id = (int(v) for v in batch["key"][0])
            records.append(
                {
                    "scene_id": scene_id,
                    "im_id": im_id,
                    "R": R[0].flatten().tolist(),
                    "t": t[0].tolist(),
                    **errs,
                }
            )
    latency = float(np.mean(times[WARMUP_IMAGES:] if len(times) > WARMUP_IMAGES else times))
    summary = {**summarise(errors, dataset.obj.diameter), "latency_ms": 1000 * latency, "fps": 1 / latency}
    return EvalResult(state["model_config"]["variant"], summary, records)


def read_groups(path: Path) -> tuple[str | None, dict[str, dict[str, list[int]]]]:
    """(split or None, {factor: {group: [sample_ids]}}) from a `scgen stats --sample-groups` file."""
    try:
        raw = json.loads(Path(path).read_text())
        groups = {f: {g: [int(i) for i in ids] for g, ids in gs.items()} for f, gs in raw["groups"].items()}
        split = raw.get("split")
    except (OSError, json.JSONDecodeError, KeyError, AttributeError, TypeError, ValueError) as exc:
        raise PosenetError(
            f"{path} is not a sample-groups file ({{seed, n, groups: {{factor: {{group: [ids]}}}}}})"
        ) from exc
    return split, groups


def by_factor(
    data: Path,
    ckpts: list[Path],
    groups_file: Path,
    split: str = "test",
    boxes: Path | None = None,
    workers: int = 2,
) -> dict[str, Any]:
    """ADD@0.02 m per (factor, group) and variant; sample ids are image ids (scgen: im_id = sample_id).

    The groups file's own split, when it names one, overrides `split`. A grouped image whose target is
    not visible is not evaluated; `n` gives the images each group's value is over (None when 0).
    """
    file_split, groups = read_groups(groups_file)
    split = file_split or split
    wanted = {i for gs in groups.values() for ids in gs.values() for i in ids}
    per_variant: dict[str, list[dict[int, float]]] = {}
    for ckpt in ckpts:
        result = evaluate(data, ckpt, split, boxes, image_ids=wanted, workers=workers)
        per_variant.setdefault(result.variant, []).append({r["im_id"]: r["add_m"] for r in result.records})
    evaluated = set.intersection(*(set(run) for runs in per_variant.values() for run in runs))

    def recall(ids: list[int], runs: list[dict[int, float]]) -> float | None:
        ids = [i for i in ids if i in evaluated]
        return float(np.mean([np.mean([run[i] < 0.02 for i in ids]) for run in runs])) if ids else None

    return {
        "metric": "add_0.02m",
        "split": split,
        "columns": list(per_variant),
        "runs": {v: len(r) for v, r in per_variant.items()},
        "n": {f: {g: len(set(ids) & evaluated) for g, ids in gs.items()} for f, gs in groups.items()},
        "groups": {
            f: {g: {v: recall(ids, runs) for v, runs in per_variant.items()} for g, ids in gs.items()}
            for f, gs in groups.items()
        },
    }


def format_table(header: list[str], rows: list[list[str]]) -> str:
    """Columns padded to their widest cell; the first column left-aligned, the rest right-aligned."""
    cells = [header, *rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    lines = [
        "  ".join(
            c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths, strict=True))
        )
        for r in cells
    ]
    return "\n".join([lines[0], "-" * len(lines[0]), *lines[1:]])
