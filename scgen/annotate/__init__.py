"""Annotation: pure numpy on Buffers (no renderer imports)."""

from scgen.annotate.annotate import Annotation, annotate, annotate_objects

__all__ = ["Annotation", "annotate", "annotate_objects"]
