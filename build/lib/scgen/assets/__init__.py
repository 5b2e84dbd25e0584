"""Procedural assets: the bundled spacecraft model builder, and where the built model lives."""

from importlib.resources import files
from pathlib import Path

# the built model ships inside the package (package data), so an installed wheel finds it anywhere
ASSET_DIR = Path(str(files(__name__) / "spacecraft"))
