"""One exception type for bad user input: the CLIs print it as a one-line error and exit non-zero."""

from clishell.errors import UserError


class ScgenError(UserError):
    """A problem with the user's input (mesh, config, paths, ranges) or a dataset on disk."""
