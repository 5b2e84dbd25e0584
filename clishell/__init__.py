"""The command-line shell both `scgen` and `posenet` stand in, owned by neither: the user-error type their
errors derive from (`errors`: no imports, so scgen's bottom floor may derive from it) and the click group
that turns a user error or an OSError into one `Error:` line and exit status 1 for every command
(`group`), and the option types both share (`types`). It imports click and the standard library only
(tests/test_layering.py).
"""
