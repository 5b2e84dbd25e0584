"""Annotation: pure numpy on Buffers (no renderer imports)."""

from scgen.annotate.annotate import Annotation, annotate

__all__ = ["Annotation", "annotate"]
