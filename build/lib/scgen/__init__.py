"""scgen: dense-labelled synthetic 6D-pose datasets of one spacecraft.

`scgen.Generator` is the library entry point (see scgen.generator); it is imported on first use so
that `scgen --help` stays fast.
"""

from typing import Any

__version__ = "0.1.0"
__all__ = ["Generator", "Sample"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from scgen import generator

        return getattr(generator, name)
    raise AttributeError(f"module 'scgen' has no attribute {name!r}")
