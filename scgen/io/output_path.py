"""The one rule for an output path, checked before any work starts: its missing parent folders are made
when it is written, so what must hold now is that the nearest existing ancestor is a writable folder and
the path itself is not in the way (a file where a folder goes, or an output that exists without
`--overwrite`)."""

from __future__ import annotations

import os
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
    ancestor = existing_parent(path if not path.exists() else path.parent)
    if not ancestor.is_dir():
        raise ScgenError(f"{what} {path} cannot be made: {ancestor} is a file, not a folder")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise ScgenError(f"{what} {path} is not writable ({ancestor} is read-only)")


def make_output_folder(path: Path) -> Path:
    """Make the folder checked by check_output (and its parents); a failure is one ScgenError line."""
    try:
        Path(path).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ScgenError(f"cannot make output folder {path}: {exc.strerror or exc}") from exc
    return Path(path)


def write_output(path: Path, data: str | bytes) -> Path:
    """Write an output file checked by check_output: its missing parents made, the file atomically (a reader
    never sees half of it); a failure is one ScgenError line."""
    path = Path(path)
    make_output_folder(path.parent)
    try:
        atomic_write_bytes(path, data.encode() if isinstance(data, str) else data)
    except OSError as exc:
        raise ScgenError(f"cannot write {path}: {exc.strerror or exc}") from exc
    return path
