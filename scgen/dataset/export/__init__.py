"""`scgen export`: a finished scgen dataset in the layouts other toolchains read, split kept.

FORMATS is the registry: a new format is one module that defines `FORMAT` (an ExportFormat: name, help
lines, writer) plus its entry below; `scgen export`'s choices and help come from it. Input, format and OUT
are checked before anything is written; the export is written into a folder beside OUT that becomes OUT
only once complete.
"""

from __future__ import annotations

from pathlib import Path

from scgen.dataset.export import coco, speedplus
from scgen.dataset.export.output import IMAGE_MODES, ExportFormat, check_out, staged
from scgen.dataset.export.source import read_source
from scgen.errors import ScgenError

FORMATS: dict[str, ExportFormat] = {f.name: f for f in (speedplus.FORMAT, coco.FORMAT)}


def export_dataset(root: str | Path, fmt: str, out: str | Path, overwrite: bool = False,
                   images: str | None = None, progress: bool = False) -> dict[str, int]:  # fmt: skip
    """Export the dataset at `root` as `fmt` into `out`; returns the number of images per file written.

    `images` (formats that write images): copy (default), hardlink or symlink the rendered images. Every
    image is decoded before anything is written: a dataset with one that cannot be read is refused.
    """
    if fmt not in FORMATS:
        raise ScgenError(f"unknown export format '{fmt}' (choose from {', '.join(FORMATS)})")
    if images is not None and not FORMATS[fmt].writes_images:
        with_images = ", ".join(f.name for f in FORMATS.values() if f.writes_images)
        raise ScgenError(f"--images applies to --format {with_images} only ({fmt} writes no images)")
    if images is not None and images not in IMAGE_MODES:
        raise ScgenError(f"unknown --images '{images}' (choose from {', '.join(IMAGE_MODES)})")
    out = Path(out)
    check_out(Path(root), out, overwrite)  # before the images are read: the quick refusals first
    source = read_source(root, progress)
    with staged(out) as tmp:
        return FORMATS[fmt].run(source, tmp, images)
