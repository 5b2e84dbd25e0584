"""`scgen stats`: the metadata groups of the paper's robustness table, per split, plus plots and the
fixed per-group sample lists used by group-wise evaluation (500 per group in the paper)."""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

import numpy as np

from scgen.dataset.layout import object_names, open_dataset, read_metadata
from scgen.dataset.splits import SPLITS
from scgen.errors import ScgenError
from scgen.io import bop
from scgen.scenes.factors import FACTOR_GROUPS, distance_groups, occlusion_group, view_direction
from scgen.scenes.geometry import quat_to_matrix


def group_labels(rows: list[dict[str, str]]) -> dict[str, list[str]]:
    """Each factor's group label for every row (distance thirds over these rows' range); '-' where a
    dataset from before a factor was recorded has no column for it."""
    labels = {f: [r.get(f, "-") for r in rows] for f in FACTOR_GROUPS if f != "distance"}
    labels["distance"], _ = distance_groups(np.array([float(r["distance_m"]) for r in rows]))
    return labels


def select_rows(root: str | Path, split: str | None) -> dict[str, list[dict[str, str]]]:
    rows = read_metadata(root)
    if split is not None and split not in SPLITS:
        raise ScgenError(f"unknown split '{split}' (choose from {', '.join(SPLITS)})")
    names = [split] if split else [s for s in SPLITS if any(r["split"] == s for r in rows)]
    return {s: [r for r in rows if r["split"] == s] for s in names}


def compute_stats(root: str | Path, split: str | None = None, min_group: int = 500) -> dict[str, Any]:
    """{"splits": {SPLIT: {"n", "factors": {FACTOR: {GROUP: COUNT}}, "shares", "distance_edges_m",
    "below_min"}}, "min_group"}."""
    out: dict[str, Any] = {"min_group": min_group, "splits": {}}
    names = object_names(open_dataset(root)[1])
    for name, rows in select_rows(root, split).items():
        labels = group_labels(rows)
        factors = {f: {g: labels[f].count(g) for g in groups} for f, groups in FACTOR_GROUPS.items()}
        extra = {f: sorted(set(labels[f]) - set(FACTOR_GROUPS[f])) for f in FACTOR_GROUPS}
        for f, groups in extra.items():  # e.g. user backgrounds: counted, never dropped
            for g in groups:
                factors[f][g] = labels[f].count(g)
        n = len(rows)
        _, edges = distance_groups(np.array([float(r["distance_m"]) for r in rows]))
        out["splits"][name] = {
            "n": n,
            "factors": factors,
            "shares": {f: {g: (c / n if n else 0.0) for g, c in gs.items()} for f, gs in factors.items()},
            "distance_edges_m": edges,
            "below_min": [f"{f}/{g}" for f, gs in factors.items() for g, c in gs.items() if c < min_group],
        }
        if rows and "sequence_id" in rows[0]:
            out["splits"][name]["sequences"] = sequence_counts(rows)
        if len(names) > 1:
            out["splits"][name]["objects"] = object_counts(root, name, names)
    return out


VISIB_QUANTILES = (0.0, 0.25, 0.5, 0.75, 1.0)  # the per-object visib_fract quantiles stats reports


def object_counts(root: str | Path, split: str, names: dict[int, str]) -> dict[str, Any]:
    """Per obj_id of a dataset with several labelled objects (its name: `names`), from the split's
    scene_gt.json and scene_gt_info.json (metadata.csv describes the target only): instances, images
    holding at least one, visib_fract quantiles, and the occlusion factor's groups of 1 - visib_fract
    (hidden by another object or cut by the image border alike)."""
    fractions: dict[int, list[float]] = {obj_id: [] for obj_id in names}
    images: dict[int, int] = dict.fromkeys(names, 0)
    for scene in bop.scene_dirs(Path(root), split):
        gt, infos = (bop.read_json(bop.scene_file(scene, n)) for n in ("scene_gt", "scene_gt_info"))
        for im_id, entries in gt.items():
            for e, info in zip(entries, infos[im_id], strict=True):
                fractions.setdefault(e["obj_id"], []).append(float(info["visib_fract"]))
            for obj_id in {e["obj_id"] for e in entries}:
                images[obj_id] = images.get(obj_id, 0) + 1
    out = {}
    for obj_id, fs in sorted(fractions.items()):
        groups = [occlusion_group(1.0 - f) for f in fs]
        out[str(obj_id)] = {
            "name": names.get(obj_id, "?"),
            "instances": len(fs),
            "images": images.get(obj_id, 0),
            "visib_fract_quantiles": {str(q): float(np.quantile(fs, q)) for q in VISIB_QUANTILES}
            if fs
            else {},
            "occlusion": {g: groups.count(g) for g in FACTOR_GROUPS["occlusion"]},
        }
    return out


SEQUENCE_GROUPS = ("profile", "attitude_mode")  # a sequence dataset's per-sequence factors (metadata.csv)


def sequence_counts(rows: list[dict[str, str]]) -> dict[str, Any]:
    """A sequence dataset's split by whole sequences: how many, their frames, the sequences of each
    profile and attitude mode, and the share of frames in eclipse."""
    first: dict[str, dict[str, str]] = {}
    for r in rows:
        first.setdefault(r["sequence_id"], r)
    seqs = list(first.values())
    return {
        "n": len(seqs),
        "frames": len(rows),
        **{
            g: {v: [r[g] for r in seqs].count(v) for v in sorted({r[g] for r in seqs})}
            for g in SEQUENCE_GROUPS
        },
        "eclipse_share": sum(r["eclipse"] == "1" for r in rows) / len(rows),
    }


def format_table(stats: dict[str, Any]) -> str:
    """Aligned human table: factor, group, then count and share per split; '*' marks ineligible groups."""
    splits = list(stats["splits"])
    header = ["factor", "group"] + [f"{s} (n={stats['splits'][s]['n']})" for s in splits]
    lines = [header]
    for factor in FACTOR_GROUPS:
        groups = list(dict.fromkeys(g for s in splits for g in stats["splits"][s]["factors"][factor]))
        for k, group in enumerate(groups):
            cells = [factor if k == 0 else "", group]
            for s in splits:
                st = stats["splits"][s]
                c = st["factors"][factor].get(group, 0)
                mark = "*" if c < stats["min_group"] else " "
                cells.append(f"{c:>7d} {100 * st['shares'][factor].get(group, 0.0):5.1f}%{mark}")
            lines.append(cells)
    text = aligned(lines)
    text += f"\n* fewer than {stats['min_group']} samples: not eligible for group-wise evaluation"
    return text + format_sequences(stats) + format_objects(stats)


def aligned(lines: list[list[str]]) -> str:
    """Rows of cells as text, each column as wide as its widest cell."""
    widths = [max(len(row[i]) for row in lines) for i in range(len(lines[0]))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) for row in lines)


def format_objects(stats: dict[str, Any]) -> str:
    """The per-object table of a dataset with several labelled objects (empty for one object)."""
    occlusion = FACTOR_GROUPS["occlusion"]
    header = ["split", "obj_id", "name", "instances", "images", "visib_fract min/q25/median/q75/max",
              *occlusion]  # fmt: skip
    lines = [header]
    for name, st in stats["splits"].items():
        for obj_id, o in st.get("objects", {}).items():
            q = "/".join(f"{v:.2f}" for v in o["visib_fract_quantiles"].values()) or "-"
            counts = [str(o["occlusion"][g]) for g in occlusion]
            lines.append([name, obj_id, o["name"], str(o["instances"]), str(o["images"]), q, *counts])
    if len(lines) == 1:
        return ""
    return "\nobjects (scene_gt instances; occlusion groups of 1 - visib_fract):\n" + aligned(lines)


def format_sequences(stats: dict[str, Any]) -> str:
    """The per-sequence lines of a sequence dataset's stats (empty for independent samples)."""
    lines = []
    for name, st in stats["splits"].items():
        if "sequences" in st:
            q = st["sequences"]
            groups = "; ".join(", ".join(f"{v} {c}" for v, c in q[g].items()) for g in SEQUENCE_GROUPS)
            lines.append(f"{name}: {q['n']} sequences, {q['frames']} frames ({groups}); "
                         f"{q['eclipse_share']:.0%} of the frames in eclipse")  # fmt: skip
    return "\n" + "\n".join(lines) if lines else ""


def to_csv(stats: dict[str, Any]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["split", "factor", "group", "count", "share", "eligible"])
    for s, st in stats["splits"].items():
        for f, groups in st["factors"].items():
            for g, c in groups.items():
                w.writerow([s, f, g, c, f"{st['shares'][f][g]:.6f}", int(c >= stats["min_group"])])
        for obj_id, o in st.get("objects", {}).items():  # factor "occlusion:obj_id": 1 - visib_fract
            n = o["instances"]
            for g, c in o["occlusion"].items():
                share = c / n if n else 0.0
                w.writerow([s, f"occlusion:{obj_id}", g, c, f"{share:.6f}", int(c >= stats["min_group"])])
    return buf.getvalue()


def sample_groups(root: str | Path, split: str, n: int, seed: int) -> dict[str, Any]:
    """Per factor group, n sample ids drawn without replacement with a fixed seed (all if fewer)."""
    rows = select_rows(root, split)[split]
    labels = group_labels(rows)
    ids = np.array([int(r["sample_id"]) for r in rows])
    groups: dict[str, dict[str, list[int]]] = {}
    for f, groups_of_f in FACTOR_GROUPS.items():
        groups[f] = {}
        for g in list(groups_of_f) + sorted(set(labels[f]) - set(groups_of_f)):
            members = ids[np.array(labels[f]) == g] if len(ids) else ids
            rng = np.random.default_rng([seed, sum(map(ord, f + "/" + g))])
            take = rng.choice(members, size=min(n, len(members)), replace=False) if len(members) else []
            groups[f][g] = sorted(int(x) for x in take)
    return {"split": split, "n": n, "seed": seed, "groups": groups}


def write_plots(root: str | Path, split: str | None, out_dir: Path) -> list[Path]:
    """Pose-coverage (viewing direction in the model frame) and distance histograms, one PNG each."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, rows in select_rows(root, split).items():
        view = np.array([_view_direction(r) for r in rows]) if rows else np.zeros((0, 3))
        az = np.degrees(np.arctan2(view[:, 1], view[:, 0]))
        el = np.degrees(np.arcsin(np.clip(view[:, 2], -1, 1)))
        fig, axes = plt.subplots(1, 2, figsize=(11, 4))
        h = axes[0].hist2d(
            az, np.sin(np.radians(el)), bins=(36, 18), range=[[-180, 180], [-1, 1]], cmap="magma"
        )
        fig.colorbar(h[3], ax=axes[0], label="samples")
        axes[0].set(xlabel="azimuth (deg, model frame)", ylabel="sin(elevation)",
                    title=f"{name}: viewpoint coverage (equal-area cells)")  # fmt: skip
        axes[1].hist([float(r["distance_m"]) for r in rows], bins=30, color="tab:blue")
        _, edges = distance_groups(np.array([float(r["distance_m"]) for r in rows]))
        for e in edges[1:3]:
            axes[1].axvline(e, color="tab:red", ls="--")
        axes[1].set(xlabel="camera-target distance (m)", ylabel="samples",
                    title=f"{name}: distance (dashed: near/middle/far thirds)")  # fmt: skip
        fig.tight_layout()
        path = out_dir / f"coverage_{name}.png"
        fig.savefig(path, dpi=90)
        plt.close(fig)
        written.append(path)
    return written


def _view_direction(row: dict[str, str]) -> np.ndarray:
    """The metadata row's viewing direction in the model frame (see factors.view_direction)."""
    R = quat_to_matrix(np.array([float(row[k]) for k in ("qw", "qx", "qy", "qz")]))
    return view_direction(R, np.array([float(row[k]) for k in ("tx", "ty", "tz")]))
