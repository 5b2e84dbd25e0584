"""Procedural assets: the bundled spacecraft model builder, and where the built model lives."""

from pathlib import Path

ASSET_DIR = Path(__file__).resolve().parents[2] / "assets" / "spacecraft"  # the repo's assets/spacecraft
