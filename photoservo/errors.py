"""Errors shared by every layer, and the exit status the CLI gives each.

`InputError` is bad input from a user (a file, a key, a value): the CLI prints its message as one
line and exits with status 2. Its message must name the problem (file, key, value).
`HardwareError` is a device or link that failed while in use (a bridge gone silent, a camera that
stopped delivering): one line, exit status 3.

Exit status of every verb (README "Exit status"): 0 ok / found, 1 not found, 2 bad input,
3 hardware or link failure, 128+N ended by signal N (after a controlled stop).
"""

EXIT_OK = 0
EXIT_NOT_FOUND = 1
EXIT_BAD_INPUT = 2
EXIT_HARDWARE = 3


class InputError(ValueError):
    """Bad user input: a missing/unreadable file, a wrong key or value. CLI exit status 2."""


class HardwareError(RuntimeError):
    """A device or link failed while in use (not the user's input). CLI exit status 3."""
