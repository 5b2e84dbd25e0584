"""Procedural assets: the bundled spacecraft model builder."""
