"""One click group class for every command line: user errors and OSErrors end as one `Error:` line.

Click prints a ClickException as `Error: MESSAGE` and exits 1; this group raises one for any UserError
or OSError met while a command runs, so no command carries its own decorator and a new command is
covered by being registered.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, NoReturn

import click

from clishell.errors import UserError


def os_error_line(exc: OSError) -> str:
    """An OSError as one line naming the path(s) and the reason: `PATH: No space left on device`."""
    reason = exc.strerror or str(exc)
    paths = [str(p) for p in (exc.filename, exc.filename2) if p is not None]
    return f"{' -> '.join(paths)}: {reason}" if paths else reason


@contextmanager
def one_line_errors() -> Iterator[None]:
    """Turn a UserError or an OSError raised inside into click's one-line error (exit status 1)."""
    try:
        yield
    except UserError as exc:
        raise click.ClickException(str(exc)) from None
    except OSError as exc:
        raise click.ClickException(os_error_line(exc)) from None


class OneLineErrorGroup(click.Group):
    """A click group whose every command's UserError and OSError is one `Error:` line and exit 1."""

    def invoke(self, ctx: click.Context) -> Any:
        with one_line_errors():
            return super().invoke(ctx)


def exit_with(error: UserError | OSError) -> NoReturn:
    """The same one line and exit status for code that runs before a group exists (a console script's
    guard that names a missing package before the command line imports it)."""
    try:
        with one_line_errors():
            raise error
    except click.ClickException as exc:
        exc.show()
        sys.exit(exc.exit_code)
