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
from scgen.dataset.layout import OBJ_ID, object_names, open_dataset
from scgen.errors import ScgenError

FORMATS: dict[str, ExportFormat] = {f.name: f for f in (speedplus.FORMAT, coco.FORMAT)}


def export_dataset(root: str | Path, fmt: str, out: str | Path, overwrite: bool = False,
                   images: str | None = None, progress: bool = False,
                   obj_id: int | None = None) -> dict[str, int]:  # fmt: skip
    """Export the dataset at `root` as `fmt` into `out`; returns the number of images per file written.

    `images` (formats that write images): copy (default), hardlink or symlink the rendered images.
    `obj_id` (one-object formats): the object whose labels to write, needed where the dataset has several.
    Every image is decoded before anything is written: a dataset with one that cannot be read is refused.
    """
    if fmt not in FORMATS:
        raise ScgenError(f"unknown export format '{fmt}' (choose from {', '.join(FORMATS)})")
    if images is not None and not FORMATS[fmt].writes_images:
        with_images = ", ".join(f.name for f in FORMATS.values() if f.writes_images)
        raise ScgenError(f"--images applies to --format {with_images} only ({fmt} writes no images)")
    if images is not None and images not in IMAGE_MODES:
        raise ScgenError(f"unknown --images '{images}' (choose from {', '.join(IMAGE_MODES)})")
    if obj_id is not None and not FORMATS[fmt].one_object:
        one_object = ", ".join(f.name for f in FORMATS.values() if f.one_object)
        raise ScgenError(f"--obj-id applies to --format {one_object} only ({fmt} labels every object)")
    out = Path(out)
    check_out(Path(root), out, overwrite)  # before the images are read: the quick refusals first
    if FORMATS[fmt].one_object:
        obj_id = chosen_object(root, fmt, obj_id)
    source = read_source(root, progress)
    if obj_id is not None:
        source = source.of_object(obj_id)
    with staged(out) as tmp:
        return FORMATS[fmt].run(source, tmp, images)


def chosen_object(root: str | Path, fmt: str, obj_id: int | None) -> int:
    """The object a one-object format exports: `obj_id`, which the dataset must hold, or where none is
    given the target of a one-object dataset; a dataset with several is refused naming its obj_ids."""
    names = object_names(open_dataset(root)[1])
    held = ", ".join(f"{k} ({name})" for k, name in names.items())
    if obj_id is None and len(names) > 1:
        raise ScgenError(f"{root} holds obj_ids {held}: --format {fmt} exports one, choose it with --obj-id")
    if obj_id is not None and obj_id not in names:
        raise ScgenError(f"--obj-id {obj_id} is not an object of {root} (obj_ids {held})")
    return OBJ_ID if obj_id is None else obj_id
