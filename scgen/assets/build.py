"""Build every bundled model (or those named) from code and write it in the BOP model layout:
`python -m scgen.assets.build [NAME ...]` (`make assets`), into scgen/assets/<name>/, package data."""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable

from scgen.assets.build_spacecraft import build_spacecraft
from scgen.assets.fleet import FLEET, build_fleet_model
from scgen.dataset.layout import OBJ_ID
from scgen.dataset.model_files import write_model_dir
from scgen.scenes.bundled_models import BUNDLED_MODELS
from scgen.scenes.model import TargetModel, bundled_model_dir

BUILDERS: dict[str, Callable[[], TargetModel]] = {
    "spacecraft": build_spacecraft,
    **{name: functools.partial(build_fleet_model, name) for name in FLEET},
}


def main(names: list[str]) -> None:
    """Build and write the models `names` (default: all of BUNDLED_MODELS)."""
    for name in names or BUNDLED_MODELS:
        if name not in BUILDERS:
            sys.exit(f"unknown bundled model '{name}' (choose from {', '.join(BUNDLED_MODELS)})")
        model, out = BUILDERS[name](), bundled_model_dir(name)
        write_model_dir({OBJ_ID: model}, out)
        print(f"wrote {out}: {len(model.mesh.faces)} triangles, diameter {model.diameter * 1000:.1f} mm")


if __name__ == "__main__":
    main(sys.argv[1:])
