"""Evaluation: pose errors, ADD/ADD-S/MSSD recalls, ESA score and batch-1 latency of a checkpoint on a split.

`evaluate` runs the split in batches and returns the summary and one record per instance; the latency
is measured apart, at batch 1, as `posenet bench` measures it. `by_factor` gives the paper's Table 5:
ADD@0.02 m per (factor, group) over fixed sample lists, one column per variant, checkpoints of the same
variant averaged. `evaluate_objects` scores one checkpoint per object, each on its object, and
`overall_summary` joins their summaries. `scgen.io.bop.results_csv` writes the records as a BOP19 results
file.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import DataLoader
from tqdm import tqdm

from posenet.checkpoint import load_checkpoint, load_model
from posenet.config import config_from_dict
from posenet.data import open_split
from posenet.data.boxes import Box, box_source, read_misses
from posenet.data.camera import make_camera
from posenet.data.dataset import PoseDataset
from posenet.data.object_model import ObjectModel
from posenet.errors import PosenetError
from posenet.evaluation.metrics import TURNED_DEG, headline_add, sample_errors, summarise
from posenet.evaluation.options import BATCH_SIZE
from posenet.export.bench import dummy_inputs, measure_latency_ms
from posenet.geometry import decode_pose
from posenet.models import PoseNet
from posenet.predict.confidence import batch_confidences
from posenet.predict.options import SAME_CROP_IOU
from posenet.predict.ransac import PNP_LABELS, ransac_poses
from posenet.predict.recrop import box_iou, next_crop

LATENCY_WARMUP = 5  # untimed batch-1 forwards (allocator, cuDNN autotuning)
LATENCY_ITERS = 20  # timed ones; the latency is their median

# Each figure a summary table prints, in order: (label, summary key, format; "%" prints a share in percent,
# "{add}" is the headline ADD's name). The one home of these labels: `posenet eval`, the learning and the
# detector benchmarks all print their summaries through summary_rows.
SUMMARY_FIGURES: tuple[tuple[str, str, str], ...] = (
    ("instances", "n", "d"),
    ("missed (no detection: failures; errors are over the rest)", "missed", "d"),
    ("PnP failed (too few mask pixels or no RANSAC pose: failures)", "pnp_failed", "d"),
    ("rotation error, mean (deg)", "re_deg", ".2f"),
    ("rotation error, median (deg)", "re_deg_median", ".2f"),
    (f"turned poses, rotation error > {TURNED_DEG:.0f} deg (%)", "turned", "%"),
    ("rotation error, symmetry-aware, mean (deg)", "re_sym_deg", ".2f"),
    ("translation error, mean (m)", "te_m", ".4f"),
    ("translation error, median (m)", "te_m_median", ".4f"),
    ("depth error, median (% of depth)", "tz_rel_median", "%"),
    ("{add}@0.02m (%)", "add_0.02m", "%"),
    ("{add}@0.1d (%)", "add_0.1d", "%"),
    ("  ADD@0.1d of the rotation alone, at GT t (%)", "add_rot_0.1d", "%"),
    ("  ADD@0.1d of the translation alone, at GT R (%)", "te_0.1d", "%"),
    ("ADD-S@0.1d (%)", "adds_0.1d", "%"),
    ("MSSD@0.1d (%)", "mssd_0.1d", "%"),
    ("AR_MSSD (%)", "ar_mssd", "%"),
    ("ESA score", "esa", ".4f"),
    ("latency, batch 1 (ms)", "latency_ms", ".2f"),
)


@dataclass
class EvalResult:
    variant: str
    summary: dict[str, Any]  # see metrics.summarise, plus latency_ms and fps
    records: list[dict[str, Any]]  # one per instance: ids, predicted pose, errors
    errors: dict[str, list[float]]  # each error's list over the records, in their order
    diameter: float  # of the evaluated object (m)

    def summary_of(self, im_ids: Collection[int]) -> dict[str, Any]:
        """metrics.summarise over the records of the images `im_ids` only (a factor group, say)."""
        keep = [i for i, r in enumerate(self.records) if r["im_id"] in im_ids]
        errors = {k: [v[i] for i in keep] for k, v in self.errors.items()}
        return summarise(errors, self.diameter, self.summary["symmetric"])


Predictions = tuple[list[dict[str, Any]], dict[str, list[float]]]  # records, and each error's list


@torch.inference_mode()
def predict(
    model: PoseNet,
    loader: DataLoader,
    obj: ObjectModel,
    device: torch.device,
    methods: Sequence[str] = ("patch",),
    mask_type: str = "bce",
) -> dict[str, Predictions]:
    """Per PnP method (`patch`: the network's own pose; `ransac`: posenet.predict.ransac on its
    correspondences, reading its mask channel as `mask_type` trained it), records in loader order
    (scene_id, im_id, obj_id, R row-major, t in metres, the pose's confidence as predict gives it
    (posenet.predict.confidence), time_s, each error of metrics.sample_errors) and each error's list over
    them, for metrics.summarise. A RoI PnP-RANSAC cannot solve is a failure: no pose, infinite errors,
    `pnp_failed` true.

    Each batch's network forward and each method's pose solving is timed and shared evenly among its RoIs;
    time_s is the sum of these shares over the image's instances (see per_image_times; reading and
    cropping are not included).
    """
    geometry = [torch.from_numpy(a).to(device) for a in (obj.pm_points, obj.vertices, obj.symmetries)]
    results: dict[str, Predictions] = {m: ([], {}) for m in methods}
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    for batch in tqdm(loader, desc="eval", unit="batch", dynamic_ncols=True, leave=False):
        b = {k: v.to(device) for k, v in batch.items()}
        tic = time.perf_counter()
        out = model(b["roi_img"], b["roi_coord2d"])
        sync()
        forward = time.perf_counter() - tic
        for method, (records, errors) in results.items():
            tic = time.perf_counter()
            if method == "ransac":
                R, t, solved = ransac_poses(out, b, obj.extent, mask_type)
            else:
                (R, t), solved = decode_pose(out, b), torch.ones(len(out["rot6d"]), dtype=torch.bool)
            sync()
            share = (forward + time.perf_counter() - tic) / len(R)
            cameras = [make_camera(K) for K in b["K"].double().cpu().numpy()]
            confidence = batch_confidences(out, b, R, t, obj.extent, mask_type, cameras)
            errs = sample_errors(R, t, b["R"], b["t"], *geometry)
            errs = {k: v.masked_fill(~solved.to(v.device), math.inf).tolist() for k, v in errs.items()}
            for k, v in errs.items():
                errors.setdefault(k, []).extend(v)
            per_instance = [dict(zip(errs, e, strict=True)) for e in zip(*errs.values(), strict=True)]
            rows = zip(
                batch["key"].tolist(),
                R.flatten(1).tolist(),
                t.tolist(),
                solved.tolist(),
                confidence,
                per_instance,
                strict=True,
            )
            for (s, i), R_i, t_i, ok, c, e in rows:
                failed = {"R": None, "t": None, "pnp_failed": True}
                pose = {"R": R_i, "t": t_i, "confidence": c} if ok else failed
                records.append(
                    {"scene_id": s, "im_id": i, "obj_id": obj.obj_id, **pose, "time_s": share, **e}
                )
    return {m: (per_image_times(records), errors) for m, (records, errors) in results.items()}


def per_image_times(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The records with each instance's time_s replaced by the sum over its image's instances: every
    estimate of an image then carries the image's time, as BOP's results file requires."""
    total: dict[tuple[int, int], float] = {}
    for r in records:
        total[r["scene_id"], r["im_id"]] = total.get((r["scene_id"], r["im_id"]), 0.0) + r["time_s"]
    return [{**r, "time_s": total[r["scene_id"], r["im_id"]]} for r in records]


def fail_misses(
    records: list[dict[str, Any]], keys: list[str], misses: set[tuple[int, int]]
) -> tuple[list[dict[str, Any]], dict[str, list[float]]]:
    """The records with those of missed images (no detection) made failures: no pose, every error
    infinite (so below no threshold; `summarise` leaves them out of the means), `missed` true; and the
    errors' lists. `json_record` writes those errors as null."""
    out = []
    for r in records:
        if (r["scene_id"], r["im_id"]) in misses:
            r = {**r, "R": None, "t": None, "missed": True} | {k: math.inf for k in keys}
        out.append(r)
    return out, {k: [r[k] for r in out] for k in keys}


def json_record(record: dict[str, Any]) -> dict[str, Any]:
    """A record as standard JSON holds it: the infinite errors of a missed image as null."""
    return {k: None if isinstance(v, float) and math.isinf(v) else v for k, v in record.items()}


def box_description(boxes: Path | None) -> str:
    """Which boxes an evaluation used: the file and what it holds (see boxes.box_source), or GT."""
    if boxes is None:
        return "ground truth (each instance's bbox_obj)"
    return f"{boxes} ({box_source(boxes)})"


def evaluate(
    data: Path,
    ckpt: Path,
    split: str = "test",
    boxes: Path | None = None,
    image_ids: set[int] | None = None,
    workers: int = 2,
    batch_size: int = BATCH_SIZE,
    obj_id: int | None = None,
    pnp: str = "patch",
    passes: int = 1,
    same_crop_iou: float = SAME_CROP_IOU,
) -> EvalResult:
    """Run the checkpoint over the split's instances of object `obj_id` (default: the object it was
    trained on) on the current device (GPU if any), `batch_size` RoIs at a time, solving each pose with
    `pnp` (patch: the network's Patch-PnP; ransac: PnP-RANSAC on its correspondences).

    The batch size changes neither the records (beyond float rounding and their time_s) nor the summary;
    `latency_ms` is the batch-1 network forward, timed by `posenet.export.bench.measure_latency_ms` on the
    same device. With `passes` > 1 each pass after the first re-crops around the model's box at the poses
    before, where it overlaps the box before by less than `same_crop_iou` (posenet.predict.recrop.next_crop),
    as `posenet predict --passes` does.
    """
    return evaluate_pnp(data, ckpt, (pnp,), split, boxes, image_ids, workers, batch_size, obj_id, passes,
                        same_crop_iou)[pnp]  # fmt: skip


def evaluate_pnp(
    data: Path,
    ckpt: Path,
    methods: Sequence[str],
    split: str = "test",
    boxes: Path | None = None,
    image_ids: set[int] | None = None,
    workers: int = 2,
    batch_size: int = BATCH_SIZE,
    obj_id: int | None = None,
    passes: int = 1,
    same_crop_iou: float = SAME_CROP_IOU,
) -> dict[str, EvalResult]:
    """`evaluate` with each PnP method of `methods` on the same network outputs (one forward pass per
    pass; the re-crops follow the first method's poses). The summary's `box_iou` is the mean IoU of the
    crop boxes with the true ones (bbox_obj) at each pass, over the images with a box."""
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    model, state = load_model(ckpt, device)
    train_cfg = config_from_dict(state["config"])
    data_cfg = train_cfg.data
    if obj_id is not None:
        data_cfg = dataclasses.replace(data_cfg, obj_id=obj_id)
    dataset = open_split(
        data, split, data_cfg, model.config, train=False, boxes_file=boxes, image_ids=image_ids
    )
    loader = DataLoader(dataset, batch_size=batch_size, shuffle=False, num_workers=workers)
    misses = read_misses(boxes, data_cfg.obj_id) if boxes is not None else set()
    predicted = predict(model, loader, dataset.obj, device, methods, train_cfg.loss.mask_type)
    ious = [crop_iou(dataset, misses)]
    for _ in range(passes - 1):
        dataset.boxes = recrop_boxes(dataset, predicted[methods[0]][0], misses, same_crop_iou)
        predicted = predict(model, loader, dataset.obj, device, methods, train_cfg.loss.mask_type)
        ious.append(crop_iou(dataset, misses))
    latency = measure_latency_ms(model, dummy_inputs(model.config, device), LATENCY_WARMUP, LATENCY_ITERS)
    results = {}
    for method, (records, errors) in predicted.items():
        if boxes is not None:
            records, errors = fail_misses(records, list(errors), misses)
        summary = summarise(errors, dataset.obj.diameter, dataset.obj.symmetric)
        summary |= {
            "latency_ms": latency,
            "fps": 1000 / latency,
            "missed": sum(r.get("missed", False) for r in records),
            "boxes": box_description(boxes),
            "pnp": PNP_LABELS[method],
            "pnp_failed": sum(r.get("pnp_failed", False) and not r.get("missed") for r in records),
            "passes": passes,
            "same_crop_iou": same_crop_iou,
            "box_iou": ious,
        }
        variant = state["model_config"]["variant"]
        results[method] = EvalResult(variant, summary, records, errors, dataset.obj.diameter)
    return results


def crop_boxes(dataset: PoseDataset) -> list[Box]:
    """The box each instance of `dataset` is cropped around, in its order (its box file's, else GT)."""
    return [dataset.boxes[i.key] if dataset.boxes is not None else i.bbox_obj for i in dataset.instances]


def crop_iou(dataset: PoseDataset, misses: set[tuple[int, int]]) -> float:
    """Mean IoU of the crop boxes with the true ones (bbox_obj) over the instances of images not missed."""
    pairs = zip(dataset.instances, crop_boxes(dataset), strict=True)
    values = [box_iou(box, inst.bbox_obj) for inst, box in pairs if inst.key not in misses]
    return float(np.mean(values)) if values else math.nan


def recrop_boxes(
    dataset: PoseDataset, records: list[dict[str, Any]], misses: set[tuple[int, int]], same_crop_iou: float
) -> dict[tuple[int, int], Box]:
    """Each image's next crop box: the model's box at its pose in `records` (`predict`'s, in the dataset's
    order); a missed image, one without a pose, or one with no next crop (posenet.predict.recrop.next_crop:
    its pose projects nowhere, or its box is the same crop) keeps its box, and so its pose."""
    out = {}
    for inst, box, r in zip(dataset.instances, crop_boxes(dataset), records, strict=True):
        again = None
        if inst.key not in misses and r["R"] is not None:
            camera = make_camera(inst.K, inst.dist, inst.image_size)
            R = np.asarray(r["R"], np.float64).reshape(3, 3)
            again = next_crop(dataset.obj, R, np.asarray(r["t"], np.float64), camera, box, same_crop_iou)
        out[inst.key] = again if again is not None else box
    return out


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
    obj_id: int | None = None,
    pnp: Sequence[str] = ("patch",),
) -> dict[str, Any]:
    """ADD@0.02 m (the headline ADD: ADD-S for a symmetric object, `add_metric`) per (factor, group) and
    variant; sample ids are image ids (scgen: im_id = sample_id). With PnP methods other than Patch-PnP in
    `pnp`, each variant has a column per method, named `variant` (Patch-PnP) or `variant PnP-RANSAC`.

    With a box file, `groups` is on those boxes and `groups_gt_boxes` on the ground-truth boxes, so each
    group shows the gap the detector costs. The groups file's own split, when it names one, overrides
    `split`. A grouped image whose target is not visible is not evaluated; `n` gives the images each
    group's value is over (None when 0).
    """
    file_split, groups = read_groups(groups_file)
    split = file_split or split
    wanted = {i for gs in groups.values() for ids in gs.values() for i in ids}
    names: set[str] = set()

    def per_variant(box_file: Path | None) -> dict[str, list[dict[int, float]]]:
        runs: dict[str, list[dict[int, float]]] = {}
        for ckpt in ckpts:
            results = evaluate_pnp(data, ckpt, pnp, split, box_file, wanted, workers, batch_size, obj_id)
            for method, result in results.items():
                key, name = headline_add(result.summary["symmetric"])
                names.add(name)
                column = result.variant if method == "patch" else f"{result.variant} {PNP_LABELS[method]}"
                runs.setdefault(column, []).append({r["im_id"]: r[key] for r in result.records})
        return runs

    tables = {"groups": per_variant(boxes)} | ({"groups_gt_boxes": per_variant(None)} if boxes else {})
    evaluated = set.intersection(*(set(run) for runs in tables["groups"].values() for run in runs))

    def recall(ids: list[int], runs: list[dict[int, float]]) -> float | None:
        ids = [i for i in ids if i in evaluated]
        return float(np.mean([np.mean([run[i] < 0.02 for i in ids]) for run in runs])) if ids else None

    return {
        "metric": "add_0.02m",
        "add_metric": "/".join(sorted(names)),
        "split": split,
        "boxes": box_description(boxes),
        "columns": list(tables["groups"]),
        "runs": {v: len(r) for v, r in tables["groups"].items()},
        "n": {f: {g: len(set(ids) & evaluated) for g, ids in gs.items()} for f, gs in groups.items()},
    } | {
        name: {
            f: {g: {v: recall(ids, runs) for v, runs in table.items()} for g, ids in gs.items()}
            for f, gs in groups.items()
        }
        for name, table in tables.items()
    }


def summary_rows(
    summaries: Sequence[Mapping[str, Any]], keys: Collection[str] | None = None
) -> list[list[str]]:
    """Table rows [label, one cell per summary] of the SUMMARY_FIGURES named in `keys` (default: every
    figure the summaries hold), in SUMMARY_FIGURES' order; a missing or nan value prints as "-"."""

    def cell(summary: Mapping[str, Any], key: str, fmt: str) -> str:
        value = summary.get(key)
        if value is None or (isinstance(value, float) and math.isnan(value)):
            return "-"
        return f"{100 * value:.2f}" if fmt == "%" else format(value, fmt)

    wanted = keys if keys is not None else {k for k in summaries[0] if all(k in s for s in summaries)}
    add = summaries[0]["add_metric"]
    return [
        [label.format(add=add), *(cell(s, key, fmt) for s in summaries)]
        for label, key, fmt in SUMMARY_FIGURES
        if key in wanted
    ]


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


def _percent(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.2f}"


def by_factor_table(res: dict[str, Any]) -> str:
    """`by_factor`'s result as a table: a column per variant (and PnP method), and with a box file each
    one's gap to the same on ground-truth boxes."""
    cols, gt = res["columns"], res.get("groups_gt_boxes")
    header = [f"{res['add_metric']}@0.02m (%)", "n"]
    header += [h for c in cols for h in ((c, f"{c} vs GT boxes (pp)") if gt else (c,))]
    rows = []
    for factor, groups in res["groups"].items():
        for group, vals in groups.items():
            row = [f"{factor}/{group}", str(res["n"][factor][group])]
            for c in cols:
                row.append(_percent(vals[c]))
                if gt:
                    row.append(_gap(vals[c], gt[factor][group][c]))
            rows.append(row)
    return format_table(header, rows)


def _gap(value: float | None, on_gt: float | None) -> str:
    """The gap in percentage points of a figure on detected boxes to the same on GT boxes."""
    return "-" if value is None or on_gt is None else f"{100 * (value - on_gt):+.2f}"


COUNTS = ("n", "missed", "pnp_failed")  # summed over objects in the overall row
WEIGHTED = ("re_deg", "re_sym_deg", "te_m", "add_0.02m", "add_0.1d", "adds_0.1d", "mssd_0.1d", "add_rot_0.1d",
            "te_0.1d", "ar_mssd", "esa", "turned")  # fmt: skip  # means and shares: instance-weighted


def evaluate_objects(
    data: Path, ckpts: Sequence[Path], method: str = "patch", **kw: Any
) -> dict[int, EvalResult]:
    """Each pose checkpoint on the instances of its own object (its config's data.obj_id; GDRNPP's one
    network per object), solved with `method`; `kw` as evaluate_pnp's. Two checkpoints of one object are
    refused: compare those with `by_factor`."""
    objects: dict[int, Path] = {}
    for ckpt in ckpts:  # every object named before any work
        obj_id = config_from_dict(load_checkpoint(ckpt, kind="pose")["config"]).data.obj_id
        if obj_id in objects:
            raise PosenetError(f"{objects[obj_id]} and {ckpt} are both of object {obj_id}: several --ckpt "
                               f"score one object each; those of one object are only compared with "
                               f"--by-factor")  # fmt: skip
        objects[obj_id] = ckpt
    return {k: evaluate_pnp(data, ckpt, (method,), **kw)[method] for k, ckpt in objects.items()}


def overall_summary(summaries: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The summaries of several objects as one: counts summed, means and recalls weighted by each object's
    instances (COUNTS, WEIGHTED); medians and latency, which do not combine, left out."""

    def weighted(key: str) -> float:
        pairs = [(s["n"], s[key]) for s in summaries if s["n"] and not math.isnan(s[key])]
        total = sum(w for w, _ in pairs)
        return sum(w * v for w, v in pairs) / total if total else math.nan

    names = {s["add_metric"] for s in summaries}
    out: dict[str, Any] = {k: sum(s[k] for s in summaries) for k in COUNTS}
    out |= {k: weighted(k) for k in WEIGHTED} | {"symmetric": any(s["symmetric"] for s in summaries)}
    return out | {"add_metric": names.pop() if len(names) == 1 else "ADD(-S)", "boxes": summaries[0]["boxes"]}
