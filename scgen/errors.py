"""One exception type for bad user input: the CLI prints it as a one-line error and exits non-zero."""


class ScgenError(Exception):
    """A problem with the user's input (mesh, config, paths, ranges) or a dataset on disk."""
