"""The `scgen` command line: parses options and calls the library; errors are one line, exit non-zero."""

from __future__ import annotations

import functools
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from clishell.group import OneLineErrorGroup
from scgen.dataset.export import FORMATS as EXPORT_FORMATS
from scgen.dataset.export.output import IMAGE_MODES
from scgen.dataset.layout import RGB_FORMATS
from scgen.errors import ScgenError
from scgen.io.camera_presets import CAMERA_PRESETS
from scgen.io.cores import usable_cores
from scgen.scenes.bundled_models import BUNDLED_MODELS, DEFAULT_MODEL
from scgen.scenes.factors import FACTOR_GROUPS


def parse_resolution(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    m = re.fullmatch(r"(\d+)[xX](\d+)", text.strip())
    if not m or int(m.group(1)) <= 0 or int(m.group(2)) <= 0:
        raise ScgenError(f"--resolution must be WxH with positive integers, got '{text}'")
    return int(m.group(1)), int(m.group(2))


def parse_shard(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"(\d+)/(\d+)", text.strip())
    if not m:
        raise ScgenError(f"--shard must be i/N (e.g. 0/4), got '{text}'")
    return int(m.group(1)), int(m.group(2))


def scene_options(command: Callable[..., Any]) -> Callable[..., Any]:
    """The options render and preview share: which renderer, seed, target mesh and sampling config."""
    options = [
        click.option("--backend", default="blender", show_default=True,
                     help="Renderer: blender (Cycles) or mitsuba."),
        click.option("--seed", type=int, default=0, show_default=True,
                     help="Dataset seed: sample i of seed s never changes."),
        click.option("--model", "model_path", type=click.Path(path_type=Path), default=None,
                     help=f"Target: a bundled model ({' | '.join(BUNDLED_MODELS)}; default "
                          f"{DEFAULT_MODEL}) or a mesh file (OBJ/PLY/GLB/STL)."),
        click.option("--keep-scale", is_flag=True,
                     help="Keep the mesh's own scale (metres) instead of a 0.2 m diameter."),
        click.option("--config", "config_path", type=click.Path(path_type=Path), default=None,
                     help="TOML/YAML file overriding any sampling distribution (see docs/config.md)."),
        click.option("--camera", "camera", default=None,
                     help=f"Camera preset: {' | '.join(CAMERA_PRESETS)} (default: the config's "
                          "camera.preset, else default). The config's camera table overrides it key by key."),
    ]  # fmt: skip
    for option in reversed(options):
        command = option(command)
    return command


def sequence_preview(command: Callable[..., Any]) -> Callable[..., Any]:
    """preview's --sequence K: an animated GIF of sequence K of a [sequence] config instead of the sheet.
    A wrapper around the command, so that preview's own parameters stay as they are."""

    @functools.wraps(command)
    def wrapper(*args: Any, sequence: int | None = None, **kwargs: Any) -> Any:
        if sequence is None:
            return command(*args, **kwargs)
        return _preview_sequence(sequence, **kwargs)

    option = click.option(
        "--sequence", type=int, default=None,
        help="Write OUT/sequence_K.gif (its frames also as OUT/sequence_K.png) instead: every frame of "
        "sequence K of a [sequence] config, the target's outline and axes drawn.",
    )  # fmt: skip
    return option(wrapper)


def _preview_sequence(sequence: int, out: Path, backend: str, seed: int, model_path: Path | None,
                      keep_scale: bool, config_path: Path | None, camera: str | None, resolution: str,
                      quality: str, overwrite: bool = False, **_: Any) -> None:  # fmt: skip
    from scgen.generator import Generator
    from scgen.io.output_path import check_output
    from scgen.preview import build_sequence_preview, contact_sheet, save_gif, save_png
    from scgen.scenes.motion.sequence import is_sequence

    if sequence < 0:
        raise ScgenError(f"--sequence must be a sequence id >= 0, got {sequence}")
    path, sheet = Path(out) / f"sequence_{sequence}.gif", Path(out) / f"sequence_{sequence}.png"
    check_output(Path(out), folder=True, overwrite=True)
    for p in (path, sheet):
        check_output(p, folder=False, overwrite=overwrite)
    generator = Generator.load(model_path, config_path, seed, parse_resolution(resolution), keep_scale,
                               camera=camera, backend=backend, quality=quality)  # fmt: skip
    if not is_sequence(generator.cfg):
        raise ScgenError("--sequence needs a --config with a [sequence] table (docs/config.md#sequence)")
    frames = build_sequence_preview(generator, sequence)
    save_gif(frames, path)
    save_png(contact_sheet(frames), sheet)
    click.echo(f"wrote {path} and {sheet.name} ({len(frames)} frames of sequence {sequence}, {backend})")


@click.group(cls=OneLineErrorGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="scgen", prog_name="scgen")
def main() -> None:
    """scgen: dense-labelled synthetic 6D-pose datasets of one spacecraft (BOP layout + xyz maps)."""


@main.command()
@click.option(
    "--n", "n", type=int, required=True,
    help="Number of samples (sample ids 0..n-1), or of sequences with a [sequence] config table.",
)  # fmt: skip
@click.option(
    "--out", type=click.Path(path_type=Path), required=True, help="Dataset folder (created or resumed)."
)
@scene_options
@click.option(
    "--backgrounds",
    "backgrounds_dir",
    type=click.Path(path_type=Path),
    default=None,
    help="Folder of your own background images: adds the background kind 'user'.",
)
@click.option("--resolution", default=None, help="Image size WxH (default 640x480); keeps the field of view.")
@click.option("--quality", default="default", show_default=True, help="draft | default | high.")
@click.option("--device", default="auto", show_default=True, help="Blender device: auto | cpu | gpu.")
@click.option(
    "--split-by",
    type=click.Choice(["factors", "random"]),
    default="factors",
    show_default=True,
    help="Split whole factor combinations (test configurations unseen in training) or images.",
)
@click.option(
    "--split", "split_text", default="0.7,0.1,0.2", show_default=True, help="train,val,test ratios."
)
@click.option("--shard", "shard_text", default="0/1", show_default=True, help="Render only shard i of N.")
@click.option(
    "--workers",
    type=int,
    default=None,
    help="Worker processes/actors (default: the cores it may use). Blender's workers share the cores; "
    "Mitsuba's render on one thread each, so that its images are the same whatever the count.",
)
@click.option(
    "--executor",
    type=click.Choice(["local", "ray"]),
    default="local",
    show_default=True,
    help="local processes, or Ray actors on a cluster (pip install 'scgen[ray]').",
)
@click.option("--ray-address", default=None, help="Ray cluster address (default: start a local Ray).")
@click.option(
    "--rgb-format",
    type=click.Choice(RGB_FORMATS),
    default="auto",
    show_default=True,
    help="auto: JPEG at the camera's drawn quality where the camera has a sensor model (a twelfth of "
    "PNG's bytes, no cost to learning measured), PNG for the exact images of --camera ideal or 16 bits.",
)
@click.option("--xyz-dtype", type=click.Choice(["float16", "float32"]), default="float16", show_default=True)
@click.option(
    "--depth/--no-depth",
    "--save-depth",
    "save_depth",
    default=True,
    show_default=True,
    help="Write BOP uint16 depth maps (bop_toolkit's calc_gt_info and VSD read them). "
    "--save-depth, the old opt-in, is kept as an alias of --depth.",
)
@click.option("--quiet", is_flag=True, help="No progress bar.")
def render(
    n,
    out,
    backend,
    seed,
    model_path,
    keep_scale,
    config_path,
    camera,
    backgrounds_dir,
    resolution,
    quality,
    device,
    split_by,
    split_text,
    shard_text,
    workers,
    executor,
    ray_address,
    rgb_format,
    xyz_dtype,
    save_depth,
    quiet,
) -> None:
    """Render a dataset: RGB, masks, xyz maps, BOP JSON, metadata.csv and splits.json."""
    from scgen.dataset.splits import parse_ratios
    from scgen.dataset.writer import WriteOptions
    from scgen.run.runner import RenderJob, run_render

    res = parse_resolution(resolution)
    overrides = {"background": {"user_dir": str(backgrounds_dir)}} if backgrounds_dir else {}
    if backgrounds_dir and backgrounds_dir.is_dir():  # each image decoded before any sample is rendered
        from scgen.io.image_file import check_images
        from scgen.scenes.config.scene import USER_IMAGE_SUFFIXES

        images = sorted(p for p in backgrounds_dir.iterdir() if p.suffix.lower() in USER_IMAGE_SUFFIXES)
        check_images(images, "background image")
    job = RenderJob(
        out=out, n=n, seed=seed, backend=backend, quality=quality, device=device, model_path=model_path,
        keep_scale=keep_scale, config_path=config_path, camera=camera, resolution=res,
        overrides=overrides, split_by=split_by,
        ratios=parse_ratios(split_text), shard=parse_shard(shard_text),
        workers=workers or usable_cores(), executor=executor, ray_address=ray_address,
        write=WriteOptions(rgb_format=rgb_format, xyz_dtype=xyz_dtype, save_depth=save_depth),
    )  # fmt: skip
    summary = run_render(job, progress=not quiet)
    rate = summary["rendered"] / summary["total_s"] if summary["total_s"] > 0 else 0.0
    click.echo(
        f"{out}: rendered {summary['rendered']} (skipped {summary['skipped']} already complete), "
        f"{summary['complete']}/{summary['total']} on disk, {rate:.2f} img/s; "
        + ", ".join(f"{k} {v}" for k, v in summary["splits"].items())
    )


@main.command()
@click.argument("bop_dir", type=click.Path(path_type=Path))
@click.option("--split", default=None, help="Only this split folder (e.g. test); default: every split.")
@click.option("--workers", type=int, default=None, help="Worker processes (default: the cores it may use).")
@click.option("--overwrite", is_flag=True, help="Replace the dataset's own masks and scene_gt_info.json.")
@click.option("--xyz-dtype", type=click.Choice(["float16", "float32"]), default="float16", show_default=True)
@click.option("--quiet", is_flag=True, help="No progress bar.")
def annotate(bop_dir: Path, split: str | None, workers: int | None, overwrite: bool, xyz_dtype: str,
             quiet: bool) -> None:  # fmt: skip
    """Label any BOP dataset: xyz maps of every scene_gt instance, masks and scene_gt_info where missing."""
    from scgen.io.output_path import check_output
    from scgen.run.annotate_job import AnnotateJob, AnnotateOptions, disagreement_line, run_annotate

    check_output(bop_dir, folder=True, overwrite=True, what="dataset")  # labelled in place, resumed
    job = AnnotateJob(bop_dir, split, workers or usable_cores(), AnnotateOptions(xyz_dtype, overwrite))
    s = run_annotate(job, progress=not quiet)
    rate = s["instances"] / s["total_s"] if s["total_s"] > 0 else 0.0
    click.echo(
        f"{bop_dir}: annotated {s['annotated']} images ({s['instances']} instances, {rate:.1f} instances/s), "
        f"skipped {s['skipped']} already complete; scene_gt_info.json of {s['scenes']} scene(s) written"
    )
    click.echo(disagreement_line(s["disagreement"]))


@main.command()
@click.argument("dataset", type=click.Path(path_type=Path))
@click.option(
    "--workers",
    type=int,
    default=None,
    help="Processes checking scene folders (default: the cores it may use).",
)
@click.option("--quiet", is_flag=True, help="No progress bar.")
def validate(dataset: Path, workers: int | None, quiet: bool) -> None:
    """Re-check a dataset's invariants (files, masks, boxes, xyz reprojection) and print a verdict."""
    from scgen.dataset.validate import validate_dataset

    if workers is not None and workers <= 0:
        raise ScgenError(f"--workers must be positive, got {workers}")
    problems, n = validate_dataset(dataset, progress=not quiet, workers=workers or usable_cores())
    if problems:
        for p in problems[:50]:
            click.echo(f"FAIL {p}")
        raise ScgenError(f"{dataset}: {len(problems)} problem(s) in {n} samples")
    click.echo(f"OK {dataset}: {n} samples pass every check")


@main.command(help=f"Group counts of the robustness factors: {', '.join(FACTOR_GROUPS)}.")
@click.argument("dataset", type=click.Path(path_type=Path))
@click.option("--split", default=None, help="Only this split (train | val | test); default: every split.")
@click.option(
    "--json", "json_path", type=click.Path(path_type=Path), default=None, help="Write the stats as JSON."
)
@click.option(
    "--csv", "csv_path", type=click.Path(path_type=Path), default=None, help="Write the stats as CSV."
)
@click.option(
    "--plots",
    "plots_dir",
    type=click.Path(path_type=Path),
    default=None,
    help="Write pose-coverage and distance histograms (PNG) here.",
)
@click.option(
    "--min-group",
    type=int,
    default=500,
    show_default=True,
    help="Eligibility minimum per group (the paper's rule).",
)
@click.option(
    "--sample-groups",
    type=int,
    default=None,
    help="Write, per group, N sample ids for group-wise evaluation (of --split, default test).",
)
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of --sample-groups.")
@click.option(
    "--groups-out",
    type=click.Path(path_type=Path),
    default=None,
    help="Where --sample-groups writes (default DATASET/groups_SPLIT_nN_sS.json, replaced when there).",
)
@click.option("--overwrite", is_flag=True, help="Replace an existing --json, --csv, --plots or --groups-out.")
def stats(dataset, split, json_path, csv_path, plots_dir, min_group, sample_groups, seed, groups_out,
          overwrite) -> None:  # fmt: skip
    """Group counts of the robustness factors (the help lists scgen.scenes.factors.FACTOR_GROUPS)."""
    import json

    from scgen.dataset.stats import compute_stats, format_table, to_csv, write_plots
    from scgen.dataset.stats import sample_groups as draw_groups
    from scgen.io.output_path import check_output, write_output

    if sample_groups is not None and sample_groups <= 0:
        raise ScgenError(f"--sample-groups must be positive, got {sample_groups}")
    which = split or "test"
    default_groups = Path(dataset) / f"groups_{which}_n{sample_groups}_s{seed}.json"
    for path, folder in ((json_path, False), (csv_path, False), (plots_dir, True), (groups_out, False)):
        if path:
            check_output(path, folder, overwrite)
    result = compute_stats(dataset, split, min_group)
    click.echo(format_table(result))
    if json_path:
        write_output(json_path, json.dumps(result, indent=1) + "\n")
    if csv_path:
        write_output(csv_path, to_csv(result))
    if plots_dir:
        for p in write_plots(dataset, split, plots_dir):
            click.echo(f"wrote {p}")
    if sample_groups is not None:
        groups = draw_groups(dataset, which, sample_groups, seed)
        path = write_output(groups_out or default_groups, json.dumps(groups, indent=1) + "\n")
        click.echo(f"wrote {path}")


@main.command()
@click.argument("out", type=click.Path(path_type=Path))
@click.argument("shards", nargs=-1, required=True, type=click.Path(path_type=Path))
def merge(out: Path, shards: tuple[Path, ...]) -> None:
    """Join shard outputs (same seed, config and model) into OUT, as if rendered in one run."""
    from scgen.dataset.layout import MANIFEST
    from scgen.dataset.merge import merge_shards
    from scgen.io.output_path import check_output

    # OUT resumes when it holds a dataset (merge_shards refuses one of other settings), else is new or empty
    check_output(out, folder=True, overwrite=True, what="OUT")
    if out.is_dir() and not (out / MANIFEST).is_file() and any(out.iterdir()):
        raise ScgenError(f"OUT {out} is not empty and holds no dataset: merge into a new folder or a shard")
    n, total = merge_shards(out, list(shards))
    click.echo(f"{out}: {n}/{total} samples after merging {len(shards)} shard folder(s)")


@main.command(
    help="Export a dataset to another toolchain's layout, keeping its train/val/test split "
    "(docs/dataset.md).\n\n\b\n"
    + "\n".join(f"{f.name}: {f.layout}" for f in EXPORT_FORMATS.values())
    + "\n\nEvery image is decoded first: nothing is written when DATASET (one of its files unreadable), "
    "--format or OUT is refused; OUT appears only once complete."
)
@click.argument("dataset", type=click.Path(path_type=Path))
@click.option(
    "--format",
    "fmt",
    required=True,
    metavar="|".join(EXPORT_FORMATS),
    help="; ".join(f"{f.name}: {f.summary}" for f in EXPORT_FORMATS.values()) + ".",
)
@click.option(
    "--out",
    type=click.Path(path_type=Path),
    required=True,
    help="Folder to write (created; must be empty unless --overwrite).",
)
@click.option("--overwrite", is_flag=True, help="Replace a non-empty OUT.")
@click.option(
    "--images",
    default=None,
    metavar="|".join(IMAGE_MODES),
    help=", ".join(f.name for f in EXPORT_FORMATS.values() if f.writes_images)
    + " only: how the images get into OUT (default copy).",
)
@click.option(
    "--obj-id",
    type=int,
    default=None,
    help=", ".join(f.name for f in EXPORT_FORMATS.values() if f.one_object)
    + " only: the object whose poses to write (default: the target, where the dataset has one object).",
)
@click.option("--quiet", is_flag=True, help="No progress bar.")
def export(dataset: Path, fmt: str, out: Path, overwrite: bool, images: str | None, obj_id: int | None,
           quiet: bool) -> None:  # fmt: skip
    from scgen.dataset.export import export_dataset

    counts = export_dataset(dataset, fmt, out, overwrite, images, progress=not quiet, obj_id=obj_id)
    click.echo(f"{out}: {fmt} export of {dataset}, " + ", ".join(f"{k} {v}" for k, v in counts.items()))


@main.command()
@sequence_preview
@click.option("--out", type=click.Path(path_type=Path), required=True, help="Folder for preview.png.")
@click.option("--n", "n", type=int, default=16, show_default=True, help="Number of samples (ids 0..n-1).")
@scene_options
@click.option("--resolution", default="320x240", show_default=True, help="Image size WxH.")
@click.option("--quality", default="draft", show_default=True, help="draft | default | high.")
@click.option("--overwrite", is_flag=True, help="Replace an existing OUT/preview.png.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def preview(out, n, backend, seed, model_path, keep_scale, config_path, camera, resolution, quality,
            overwrite, quiet) -> None:  # fmt: skip
    """Render n samples in memory, as render would, and write OUT/preview.png: RGB, masks, xyz, factors."""
    from scgen.generator import Generator
    from scgen.io.output_path import check_output
    from scgen.preview import build_preview, save_png

    if n <= 0:
        raise ScgenError(f"--n must be a positive number of samples, got {n}")
    check_output(Path(out), folder=True, overwrite=True)  # OUT may hold other files; preview.png is checked
    check_output(Path(out) / "preview.png", folder=False, overwrite=overwrite)
    generator = Generator.load(
        model_path,
        config_path,
        seed,
        parse_resolution(resolution),
        keep_scale,
        camera=camera,
        backend=backend,
        quality=quality,
    )
    path = Path(out) / "preview.png"
    save_png(build_preview(generator, n, progress=not quiet), path)
    click.echo(f"wrote {path} ({n} samples, {backend})")


@main.command()
@click.option("--out", type=click.Path(path_type=Path), default=None, help="Also check its free space.")
def doctor(out: Path | None) -> None:
    """Check what this machine can render and train with: one line per check, its verdict and the fix.

    Exits non-zero when the default backend (blender) is installed but cannot render; a node installed
    without it (a training node, a Mitsuba-only node) gets `warn` lines naming what to install.
    """
    from scgen.doctor import FAIL, diagnose

    failed = False
    for finding in diagnose(out):
        click.echo(str(finding))
        failed |= finding.verdict == FAIL
    if failed:
        raise ScgenError("the default backend (blender) cannot render here: see the FAIL line(s) above")


if __name__ == "__main__":
    main()
