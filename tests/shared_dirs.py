"""Folders built once per test session and shared, read-only, by every module and every pytest-xdist
worker that asks for them: the small renders and tiny checkpoints many tests read."""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest
from filelock import FileLock


def session_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The session's base temp folder; under pytest-xdist each worker's base is a child of it, so the
    workers of one run meet in the parent."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


def shared_dir(tmp_path_factory: pytest.TempPathFactory, name: str, build: Callable[[Path], None]) -> Path:
    """`session_root / name`, made by `build(folder)` the first time anyone asks. Built in a sibling and
    renamed, under a file lock, so a worker never reads a half-built folder and none builds it twice."""
    out = session_root(tmp_path_factory) / name
    with FileLock(f"{out}.lock"):
        if not out.is_dir():
            partial = out.with_name(f"{name}.partial")
            shutil.rmtree(partial, ignore_errors=True)
            build(partial)
            partial.rename(out)
    return out
