"""Logging for the CLI: stdlib `logging` to stderr, `-v` / `-q` set the level, and the libraries'
own messages go the same way.

- photoservo's modules log to `logging.getLogger(__name__)`; Rerun's Python SDK logs to
  "rerun"; both reach one stderr handler on the root logger.
- `warnings.warn` (e.g. the recorder's "viewer could not be started") becomes one log line
  ("warning: ...") instead of Python's two-line file:line form.
- OpenCV writes its own WARN lines from C++ straight to the terminal; its log level follows
  ours (silent below -v, its warnings at -v, its info at -vv), so a failed device open shows
  our one-line error first, not OpenCV's.

Levels: -qq errors only, -q warnings, default info (status lines, notes), -v debug, -vv OpenCV
and Rerun detail.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import warnings
from collections.abc import Callable

# verbosity -> (our level, OpenCV's log level name)
_LEVELS = {-2: (logging.ERROR, "SILENT"), -1: (logging.WARNING, "SILENT"), 0: (logging.INFO, "SILENT"),
           1: (logging.DEBUG, "WARNING"), 2: (logging.DEBUG, "INFO")}
_CV_LEVELS = {"SILENT": 0, "FATAL": 1, "ERROR": 2, "WARNING": 3, "INFO": 4, "DEBUG": 5}


def add_verbosity_options(p: argparse.ArgumentParser, default: object = 0) -> None:
    """-v / -q (repeatable); accepted before and after the verb."""
    p.add_argument("-v", "--verbose", action="count", default=default,
                   help="more detail on stderr: -v debug, -vv also OpenCV's and Rerun's own messages")
    p.add_argument("-q", "--quiet", action="count", default=default,
                   help="less on stderr: -q warnings and errors only (no status or progress), -qq errors only")


class _Formatter(logging.Formatter):
    """'message' for info, 'warning: message' / 'error: message', 'debug [logger]: message'."""

    def format(self, record: logging.LogRecord) -> str:
        msg = record.getMessage()
        if record.exc_info and record.levelno >= logging.ERROR:
            msg += f" ({record.exc_info[1]})"
        if record.levelno >= logging.ERROR:
            return f"error: {msg}"
        if record.levelno >= logging.WARNING:
            return f"warning: {msg}"
        if record.levelno >= logging.INFO:
            return msg
        return f"debug [{record.name}]: {msg}"


def level_for(verbosity: int) -> int:
    """The logging level of a -v/-q count (verbose minus quiet)."""
    return _LEVELS[max(-2, min(2, verbosity))][0]


def setup_logging(verbosity: int) -> Callable[[], None]:
    """Install the stderr handler at the level of `verbosity` (-v count minus -q count); route
    warnings.warn and OpenCV's log through it. Returns a function that undoes it all (tests call
    `main()` many times in one process)."""
    level, cv_level = _LEVELS[max(-2, min(2, verbosity))]
    root = logging.getLogger()
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_Formatter())
    old_level = root.level
    root.addHandler(handler)
    root.setLevel(level)
    rerun_logger = logging.getLogger("rerun")
    old_rerun = rerun_logger.level
    rerun_logger.setLevel(logging.DEBUG if verbosity >= 2 else logging.WARNING)
    old_showwarning = warnings.showwarning

    def showwarning(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001
        logging.getLogger("py.warnings").warning("%s", message)

    warnings.showwarning = showwarning
    old_cv = _set_opencv_level(cv_level)

    def restore() -> None:
        root.removeHandler(handler)
        root.setLevel(old_level)
        rerun_logger.setLevel(old_rerun)
        warnings.showwarning = old_showwarning
        _set_opencv_level(old_cv)

    return restore


def _set_opencv_level(name: str | int | None) -> str | int | None:
    """Set OpenCV's own log level (before cv2 is imported: through OPENCV_LOG_LEVEL, which the
    spawned child processes inherit too); returns the previous setting for restoring."""
    if "cv2" in sys.modules:
        import cv2

        old = cv2.utils.logging.getLogLevel()
        if name is not None:
            cv2.utils.logging.setLogLevel(_CV_LEVELS[name] if isinstance(name, str) else int(name))
        return old
    old_env = os.environ.get("OPENCV_LOG_LEVEL")
    if name is None:
        os.environ.pop("OPENCV_LOG_LEVEL", None)
    else:
        os.environ["OPENCV_LOG_LEVEL"] = name if isinstance(name, str) else str(name)
    return old_env
