"""The `posenet` console script: one line naming the missing training packages, before the CLI imports them.

posenet ships in the `scgen` distribution; a rendering node installed without the `train` extra has
the command but not torch, and gets this line instead of an import traceback. A package that only some
configs need (albumentations, for the augmentation chains other than the paper's) is named when a config
selects it (posenet.doctor.check_config_packages), so a node without it runs every other command.
"""

from __future__ import annotations

from clishell.group import exit_with
from posenet.doctor import INSTALL_HINT, missing_training_modules
from posenet.errors import PosenetError


def main() -> None:
    missing = missing_training_modules()
    if missing:
        exit_with(PosenetError(f"posenet needs {', '.join(missing)}, not installed here: {INSTALL_HINT}"))
    from posenet.cli import main as cli

    cli()
