"""The one rule for an output path, checked before any work starts, and the one way outputs are written.

Its missing parent folders are made when it is written, so what must hold now is that the nearest
existing folder is writable storage (not a special file system such as /proc, not a read-only mount,
not full) and the path itself is not in the way (a file where a folder goes, or an output that exists
without `--overwrite`). What can still fail later (the disk fills up during a run) is one ScgenError
naming the file and the reason (`writing`), and what a failed write had made is removed.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from scgen.errors import ScgenError
from scgen.io.atomic import atomic_write_bytes


def existing_parent(path: Path) -> Path:
    """`path`, or its nearest ancestor that exists (absolute)."""
    p = Path(path).absolute()
    while not p.exists():
        p = p.parent
    return p


def first_missing(path: Path) -> Path | None:
    """The outermost folder that making `path` would create (`path` itself, or its first missing ancestor),
    or None when `path` exists: what a command that fails part-way removes so as to leave nothing behind."""
    p = Path(path).absolute()
    if p.exists():
        return None
    while not p.parent.exists():
        p = p.parent
    return p


def check_output(path: Path, folder: bool, overwrite: bool = False, what: str = "output") -> None:
    """Raise ScgenError naming `path` unless it can be written: as a folder (`folder`; an existing empty
    one is fine) or a file. An existing output is refused unless `overwrite`."""
    path = Path(path)
    if path.exists():
        if folder and not path.is_dir():
            raise ScgenError(f"{what} {path} exists and is not a folder")
        if not folder and path.is_dir():
            raise ScgenError(f"{what} {path} is a folder, not a file")
        if not overwrite and (not folder or any(path.iterdir())):
            raise ScgenError(f"{what} {path} exists (give --overwrite to replace it)")
    # the folder the first write lands in: an existing output folder itself (it may be a mount point),
    # else the nearest existing ancestor (a file is written beside itself, atomically)
    where = path.absolute() if path.is_dir() else existing_parent(path.parent if path.exists() else path)
    if not where.is_dir():
        raise ScgenError(f"{what} {path} cannot be made: {where} is a file, not a folder")
    check_storage(path, where, what)


def check_storage(path: Path, where: Path, what: str) -> None:
    """Raise ScgenError unless folder `where` can take `path`'s first file: statvfs says whether it is
    storage at all, read-only, or full."""
    fs = os.statvfs(where)
    if fs.f_blocks == 0:  # /proc, /sys and the like hold no blocks: mkdir or open fails there
        raise ScgenError(f"{what} {path} cannot be written: {where} is on a special file system, not storage")
    if fs.f_flag & os.ST_RDONLY:
        raise ScgenError(f"{what} {path} is not writable: {where} is on a read-only file system")
    if not os.access(where, os.W_OK | os.X_OK):
        raise ScgenError(f"{what} {path} is not writable ({where} is read-only)")
    if fs.f_bavail == 0:  # not one free block for the first file
        raise ScgenError(f"{what} {path} cannot be written: no space left on the file system of {where}")


@contextmanager
def writing(path: Path) -> Iterator[None]:
    """Outputs made and written inside, under `path`: an OSError (a full disk, a mount gone read-only) is
    one ScgenError naming the file and the reason, and the folders they needed that were missing are
    removed again."""
    made = first_missing(path)
    try:
        yield
    except OSError as exc:
        if made is not None:
            shutil.rmtree(made, ignore_errors=True)
        raise ScgenError(f"cannot write {exc.filename or path}: {exc.strerror or exc}") from exc


def make_output_folder(path: Path) -> Path:
    """Make the folder checked by check_output (and its parents); a failure is one ScgenError line."""
    with writing(path):
        Path(path).mkdir(parents=True, exist_ok=True)
    return Path(path)


def write_output(path: Path, data: str | bytes) -> Path:
    """Write an output file checked by check_output: its missing parents made, the file atomically (a reader
    never sees half of it); a failure is one ScgenError line and leaves nothing behind."""
    path = Path(path)
    with writing(path):
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, data.encode() if isinstance(data, str) else data)
    return path
