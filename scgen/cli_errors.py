"""Library errors as command-line errors: one line, exit status 1; shared by the scgen and posenet CLIs."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import click


def one_line_errors(*errors: type[Exception]) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Decorator for click commands: `errors` become click's one-line 'Error: ...' and exit status 1.

    Shared by the scgen and posenet command lines (each passes its own input-error type).
    """

    def decorate(fn: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(fn)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            try:
                return fn(*args, **kwargs)
            except errors as exc:
                raise click.ClickException(str(exc)) from None

        return wrapper

    return decorate
