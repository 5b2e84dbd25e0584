"""Evaluation: pose errors, ADD/ADD-S recalls, ESA score and batch-1 latency of a checkpoint on a split.

`evaluate` runs the split in batches and returns the summary and one record per instance; the latency
is measured apart, at batch 1, as `posenet bench` measures it. `by_factor` gives the paper's Table 5:
ADD@0.02 m per (factor, group) over fixed sample lists, one column per variant, checkpoints of the same
variant averaged.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import DataLoader

from posenet.bench import dummy_inputs, measure_latency_ms
from posenet.checkpoint import load_checkpoint
from posenet.config import config_from_dict
from posenet.data import open_split
from posenet.errors import PosenetError
from posenet.geometry import decode_pose
from posenet.metrics import sample_errors, summarise
from posenet.models import PoseNet, create_model

BATCH_SIZE = 32
LATENCY_WARMUP = 5  # untimed batch-1 forwards (allocator, cuDNN autotuning)
LATENCY_ITERS = 20  # timed ones; the latency is their median


@dataclass
class EvalResult:
    variant: str
    summary: dict[str, float]  # see metrics.summarise, plus latency_ms and fps
    records: list[dict[str, Any]]  # one per instance: ids, predicted pose, errors


def load_model(ckpt: Path, device: torch.device) -> tuple[PoseNet, dict[str, Any]]:
    """The network of a checkpoint, in eval mode on `device`, and the checkpoint itself."""
    state = load_checkpoint(ckpt)
    model = create_model(**state["model_config"])
    try:
        model.load_state_dict(state["model"])
    except RuntimeError as exc:
        raise PosenetError(f"checkpoint {ckpt} does not match its own model configuration") from exc
    return model.to(device).eval(), state


@torch.inference_mode()
def predict(
    model: PoseNet, loader: DataLoader, points: torch.Tensor, device: torch.device
) -> tuple[list[dict[str, Any]], dict[str, list[float]]]:
    """Records in loader order (scene_id, im_id, R row-major, t in metres, each error of
    metrics.sample_errors) and each error's list over them, for metrics.summarise."""
    records: list[dict[str, Any]] = []
    errors: dict[str, list[float]] = {}
    for batch in loader:
        b = {k: v.to(device) for k, v in batch.items()}
        R, t = decode_pose(model(b["roi_img"], b["roi_coord2d"]), b)
        errs = {k: v.tolist() for k, v in sample_errors(R, t, b["R"], b["t"], points).items()}
        for k, v in errs.items():
            errors.setdefault(k, []).extend(v)
        per_instance = [dict(zip(errs, e, strict=True)) for e in zip(*errs.values(), strict=True)]
        rows = zip(batch["key"].tolist(), R.flatten(1).tolist(), t.tolist(), per_instance, strict=True)
        records += [{"scene_id": s, "im_id": i, "R": R_i, "t": t_i, **e} for (s, i), R_i, t_i, e in rows]
    return records, errors


def evaluate(
    data: Path,
    ckpt: Path,
    split: str = "test",
    boxes: Path | None = None,
    image_ids: set[int] | None = None,
    workers: int = 2,
    batch_size: int = BATCH_SIZE,
) -> EvalResult:
    """Run the checkpoint over the split on the current device (GPU if any), `batch_size` RoIs at a time.

    The batch size changes neither the records nor the summary (beyond float rounding); `latency_ms` is
    the batch-1 network forward, timed by `posenet.bench.measure_latency_ms` on the same device.
    """
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    model, state = load_model(ckpt, device)
    cfg = config_from_dict(state["config"])
    dataset = open_split(
        data, split, cfg.data, model.config, train=False, boxes_file=boxes, image_ids=image_ids
    )
    points = torch.from_numpy(dataset.obj.pm_points).to(device)  # uniform surface points, as the PM loss
    loader = DataLoader(dataset, batch_size=batch_size, shuffle=False, num_workers=workers)
    records, errors = predict(model, loader, points, device)
    latency = measure_latency_ms(model, dummy_inputs(model.config, device), LATENCY_WARMUP, LATENCY_ITERS)
    summary = {**summarise(errors, dataset.obj.diameter), "latency_ms": latency, "fps": 1000 / latency}
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
    batch_size: int = BATCH_SIZE,
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
        result = evaluate(data, ckpt, split, boxes, wanted, workers, batch_size)
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
