"""One exception type for bad user input: the CLI prints it as a one-line error and exits non-zero."""


class PosenetError(Exception):
    """A problem with the user's input: dataset folder, box file, config, checkpoint."""
