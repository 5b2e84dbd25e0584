"""One exception type for bad user input: the CLI prints it as a one-line error and exits non-zero."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import click


class ScgenError(Exception):
    """A problem with the user's input (mesh, config, paths, ranges) or a dataset on disk."""


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
