"""Option types both command lines share."""

from __future__ import annotations

import math
from typing import Any

import click


class FiniteFloatRange(click.FloatRange):
    """click's FloatRange that also refuses nan and the infinities: a comparison with nan is always
    false, so FloatRange lets it through every bound (`--min-score nan` would be taken), and no option
    of these tools means anything at infinity."""

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number.", param, ctx)
        return number
