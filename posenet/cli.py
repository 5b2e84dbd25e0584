"""The `posenet` command line: parses options and calls the library; errors are one line, exit non-zero."""

from __future__ import annotations

import json
import os
from pathlib import Path

import click

from posenet.bench import bench
from posenet.config import load_config
from posenet.data.boxes import boxes_from_gt
from posenet.data.layout import scan_split
from posenet.errors import PosenetError
from posenet.evaluate import by_factor as run_by_factor
from posenet.evaluate import evaluate, format_table
from posenet.train import train as run_train
from posenet.viz import viz
from scgen.atomic import atomic_write_text
from scgen.cli_errors import one_line_errors

PATH = click.Path(path_type=Path)


def _percent(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.2f}"


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
def main() -> None:
    """posenet: GDR-Net / GAP-GDRNet 6D pose networks trained and evaluated on scgen (BOP-layout) datasets."""


@main.command()
@click.option(
    "--data", type=PATH, required=True, help="Dataset folder (scgen output or BOP layout + xyz maps)."
)
@click.option(
    "--out", type=PATH, required=True, help="Run folder: config.yaml, last.pt, train_log.jsonl, tb/."
)
@click.option("--config", "config", default=None, help="paper | smoke | a YAML/TOML file  [default: paper]")
@click.option(
    "--variant", default=None, help="gdrnet (default), convnext, ggca, mecs, pgsa, afr, gap-gdrnet."
)
@click.option(
    "--epochs", type=click.IntRange(min=1), default=None, help="Override optim.epochs (sets the schedule)."
)
@click.option(
    "--max-steps", type=click.IntRange(min=1), default=None, help="Stop after N steps (schedule unchanged)."
)
@click.option(
    "--resume", is_flag=True, help="Continue OUT/last.pt (with OUT/config.yaml unless --config is given)."
)
@one_line_errors(PosenetError)
def train(
    data: Path,
    out: Path,
    config: str | None,
    variant: str | None,
    epochs: int | None,
    max_steps: int | None,
    resume: bool,
) -> None:
    """Train on the dataset's train split (under torchrun: DDP over the processes)."""
    if config is None:
        saved = out / "config.yaml"
        config = str(saved) if resume and saved.is_file() else "paper"
    ckpt = run_train(
        data, out, load_config(config, variant=variant, epochs=epochs), resume=resume, max_steps=max_steps
    )
    if os.environ.get("RANK", "0") == "0":  # torchrun: one line, not one per process
        click.echo(f"checkpoint: {ckpt}")


@main.command("eval")
@click.option("--data", type=PATH, required=True, help="Dataset folder.")
@click.option(
    "--ckpt", type=PATH, required=True, multiple=True, help="Checkpoint (repeatable with --by-factor)."
)
@click.option("--split", default="test", show_default=True)
@click.option(
    "--boxes", type=PATH, default=None, help="Stored detection boxes (BOP JSON); default: GT boxes."
)
@click.option(
    "--json", "json_path", type=PATH, default=None, help="Write the summary (or factor table) as JSON."
)
@click.option("--predictions", type=PATH, default=None, help="Per-instance JSONL [default: next to --json].")
@click.option(
    "--by-factor", type=PATH, default=None, help="Sample-groups file: per-group ADD@0.02 m (Table 5)."
)
@click.option("--workers", type=click.IntRange(min=0), default=2, show_default=True, help="Loader processes.")
@one_line_errors(PosenetError)
def eval_cmd(
    data: Path,
    ckpt: tuple[Path, ...],
    split: str,
    boxes: Path | None,
    json_path: Path | None,
    predictions: Path | None,
    by_factor: Path | None,
    workers: int,
) -> None:
    """Rotation/translation error, ADD@0.02 m, ADD@0.1d, ADD-S@0.1d, ESA score and batch-1 latency."""
    if by_factor is not None:
        res = run_by_factor(data, list(ckpt), by_factor, split, boxes, workers)
        cols = res["columns"]
        rows = [
            [f"{factor}/{group}", str(res["n"][factor][group]), *(_percent(vals[c]) for c in cols)]
            for factor, groups in res["groups"].items()
            for group, vals in groups.items()
        ]
        click.echo(format_table(["ADD@0.02m (%)", "n", *cols], rows))
        if json_path is not None:
            atomic_write_text(json_path, json.dumps(res, indent=2) + "\n")
        return
    if len(ckpt) != 1:
        raise PosenetError("several --ckpt are only compared with --by-factor")
    result = evaluate(data, ckpt[0], split, boxes, workers=workers)
    s = result.summary
    rows = [
        ["samples", f"{s['n']}"],
        ["rotation error (deg)", f"{s['re_deg']:.3f}"],
        ["translation error (m)", f"{s['te_m']:.4f}"],
        ["ADD@0.02m (%)", f"{100 * s['add_0.02m']:.2f}"],
        ["ADD@0.1d (%)", f"{100 * s['add_0.1d']:.2f}"],
        ["ADD-S@0.1d (%)", f"{100 * s['adds_0.1d']:.2f}"],
        ["ESA score", f"{s['esa']:.4f}"],
        ["latency, batch 1 (ms)", f"{s['latency_ms']:.2f}"],
    ]
    click.echo(format_table([f"{result.variant} on {split}", "value"], rows))
    if predictions is None:
        predictions = (
            json_path.with_suffix(".predictions.jsonl")
            if json_path
            else ckpt[0].with_name(f"predictions_{split}.jsonl")
        )
    atomic_write_text(predictions, "".join(json.dumps(r) + "\n" for r in result.records))
    if json_path is not None:
        atomic_write_text(
            json_path, json.dumps({"variant": result.variant, "split": split, **s}, indent=2) + "\n"
        )
    click.echo(f"predictions: {predictions}")


@main.command()
@click.option("--data", type=PATH, required=True, help="Dataset folder.")
@click.option("--out", type=PATH, required=True, help="Box file to write (BOP detection JSON).")
@click.option("--split", default="test", show_default=True)
@click.option("--noise", type=click.FloatRange(min=0), default=0.0, show_default=True,
              help="Relative std of centre shift and log size change (0: exact GT boxes).")  # fmt: skip
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--obj-id", type=int, default=1, show_default=True)
@one_line_errors(PosenetError)
def boxes(data: Path, out: Path, split: str, noise: float, seed: int, obj_id: int) -> None:
    """Write one box per image of a split from the GT full-object boxes, optionally perturbed."""
    entries = boxes_from_gt([i for i in scan_split(data, split, obj_id) if i.px_count_visib > 0], noise, seed)
    atomic_write_text(out, json.dumps(entries) + "\n")
    click.echo(f"{len(entries)} boxes -> {out}")


main.add_command(bench)
main.add_command(viz)


if __name__ == "__main__":  # `python -m posenet.cli`, e.g. under `torchrun -m`
    main()
