"""The user-error type: what a command line prints as one `Error:` line, without a traceback."""


class UserError(Exception):
    """A problem with the user's input or machine that the user can fix: one line says what and where.

    scgen.errors.ScgenError and posenet.errors.PosenetError derive from it."""
