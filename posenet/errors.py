"""One exception type for bad user input: the CLI prints it as a one-line error and exits non-zero."""

from __future__ import annotations

import re

from clishell.errors import UserError

# how torch's DataLoader re-raises an exception met in a loader process: the type, then the worker's
# traceback as text, whose last line is the original "module.Type: message"
_LOADER_WRAPPED = re.compile(r"Caught PosenetError in DataLoader worker process \d+\.\n")


class PosenetError(UserError):
    """A problem with the user's input: dataset folder, box file, config, checkpoint, a sample's file.

    Met in a DataLoader process, it comes back as a PosenetError whose text is that process's whole
    traceback; it keeps only the original message, so the user still reads one line."""

    def __init__(self, message: str = "") -> None:
        if _LOADER_WRAPPED.match(message):
            last = message.rstrip().splitlines()[-1]
            message = last.split("PosenetError: ", 1)[-1]
        super().__init__(message)
