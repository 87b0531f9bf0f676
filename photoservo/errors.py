"""Errors shared by every layer.

`InputError` is bad input from a user (a file, a key, a value): the CLI prints its message as one
line and exits with status 2. Its message must name the problem (file, key, value).
"""


class InputError(ValueError):
    """Bad user input: a missing/unreadable file, a wrong key or value. CLI exit status 2."""
