"""Folders built once per test session and shared, read-only, by every module that asks for them: the
small renders and tiny checkpoints many tests read."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import pytest


def shared_dir(tmp_path_factory: pytest.TempPathFactory, name: str, build: Callable[[Path], None]) -> Path:
    """The session's `basetemp / name`, made by `build(folder)` the first time any module asks. Built in a
    sibling and renamed, so a build that fails leaves nothing another module would take as made."""
    out = tmp_path_factory.getbasetemp() / name
    if not out.is_dir():
        partial = out.with_name(f"{name}.partial")
        shutil.rmtree(partial, ignore_errors=True)
        build(partial)
        partial.rename(out)
    return out
