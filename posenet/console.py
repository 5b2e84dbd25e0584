"""The `posenet` console script: one line naming the missing training packages, before the CLI imports them.

posenet ships in the `scgen` distribution; a rendering node installed without the `train` extra has
the command but not torch, and gets this line instead of an import traceback.
"""

from __future__ import annotations

import importlib.util
import sys
import time

import posenet

TRAINING_MODULES = ("torch", "torchvision", "timm", "albumentations", "tensorboard")
INSTALL_HINT = "pip install 'scgen[train]'"


def missing_training_modules() -> list[str]:
    """The training stack's top-level modules that cannot be found here (none are imported)."""
    return [m for m in TRAINING_MODULES if importlib.util.find_spec(m) is None]


def main() -> None:
    missing = missing_training_modules()
    if missing:
        sys.exit(f"Error: posenet needs {', '.join(missing)}, not installed here: {INSTALL_HINT}")
    tic = time.perf_counter()
    from posenet.cli import main as cli

    posenet.IMPORT_SECONDS = time.perf_counter() - tic  # printed in train's start-up line
    cli()
