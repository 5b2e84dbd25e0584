"""The export's output folder: checked before anything is written, filled beside OUT, renamed at the end."""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from scgen.errors import ScgenError
from scgen.io.atomic import TMP_MARK
from scgen.io.output_path import check_output

if TYPE_CHECKING:
    from scgen.dataset.export.source import Source

IMAGE_MODES = ("copy", "hardlink", "symlink")  # how exported images refer to the rendered ones


@dataclass(frozen=True)
class ExportFormat:
    """One entry of `scgen export`'s registry (scgen.dataset.export.FORMATS): the CLI's choices and help
    come from these. `write(source, out[, images])` fills `out` and returns the images per file written;
    it takes an IMAGE_MODES value when `writes_images`. A `one_object` format labels one object per image:
    it is handed the dataset as that object's (Source.of_object, `scgen export --obj-id`)."""

    name: str
    summary: str  # one line: what the format holds
    layout: str  # what OUT holds, one line
    write: Callable[..., dict[str, int]]
    writes_images: bool = False
    one_object: bool = False

    def run(self, source: Source, out: Path, images: str | None) -> dict[str, int]:
        """Write `source` into `out`; `images` only where the format places image files."""
        return (
            self.write(source, out, images or IMAGE_MODES[0])
            if self.writes_images
            else self.write(source, out)
        )


def check_out(root: Path, out: Path, overwrite: bool) -> None:
    """OUT must lie apart from the dataset folder, then pass the one output rule (scgen.io.output_path)."""
    out_r, root_r = out.resolve(), root.resolve()
    if out_r == root_r or root_r in out_r.parents or out_r in root_r.parents:
        raise ScgenError(f"--out {out} overlaps the dataset folder {root}: choose a folder outside it")
    check_output(out, folder=True, overwrite=overwrite, what="--out")


@contextmanager
def staged(out: Path) -> Iterator[Path]:
    """A new folder beside `out` to write into: it replaces `out` when the block succeeds and is removed
    when it raises, so a failed export leaves `out` as it was."""
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}{TMP_MARK}{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)  # left by a killed export of the same process id
    tmp.mkdir()
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = out.with_name(f".{out.name}.old{TMP_MARK}{os.getpid()}")
    shutil.rmtree(old, ignore_errors=True)
    if out.exists():
        os.replace(out, old)
    os.replace(tmp, out)
    shutil.rmtree(old, ignore_errors=True)


def place_image(src: Path, dst: Path, mode: str) -> None:
    """Put a rendered image at `dst`: a copy of its bytes, a hard link or an absolute symbolic link."""
    try:
        if mode == "copy":
            shutil.copyfile(src, dst)
        elif mode == "hardlink":
            os.link(src, dst)
        else:
            dst.symlink_to(src.resolve())
    except OSError as exc:
        raise ScgenError(f"cannot {mode} {src} to {dst} ({exc.strerror}); try --images copy") from exc
