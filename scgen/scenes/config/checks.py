"""Range and choice checks of config values: one line naming the key and the bad value."""

from __future__ import annotations

import math
from typing import Any

from scgen.errors import ScgenError


def is_number(value: Any) -> bool:
    """A finite int or float (not a bool): nan passes every comparison a range check makes, and no config
    value means anything at infinity."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def check_range(name: str, value: Any, low: float) -> None:
    """[min, max] with low <= min <= max."""
    ok = isinstance(value, (list, tuple)) and len(value) == 2 and all(map(is_number, value))
    if not ok or not (low <= value[0] <= value[1]):
        raise ScgenError(f"{name} must be [min, max] with {low} <= min <= max, got {value!r}")


def check_prob(name: str, p: Any) -> None:
    if not is_number(p) or not 0.0 <= p <= 1.0:
        raise ScgenError(f"{name} must be a probability in [0, 1], got {p!r}")


def check_positive(name: str, value: Any) -> None:
    if not is_number(value) or value <= 0:
        raise ScgenError(f"{name} must be positive, got {value!r}")


def check_choice(name: str, value: Any, allowed: tuple[Any, ...]) -> None:
    if value not in allowed:
        raise ScgenError(f"{name} must be one of {', '.join(map(str, allowed))}, got {value!r}")


def check_distance(name: str, distance: dict[str, Any]) -> None:
    """A `distance` table (top-level or an `[[objects]]` entry's `name`): a metric range, or else a
    projected-diameter range in pixels."""
    if distance["range_m"] is None:
        check_range(f"{name}.min_px/max_px", [distance["min_px"], distance["max_px"]], low=1.0)
    else:
        check_range(f"{name}.range_m", distance["range_m"], low=1e-6)
