"""Ctrl-C, SIGTERM and SIGHUP end a verb the same way: a controlled stop.

`stop_on_signals()` turns each of them into a `StopSignal` (a KeyboardInterrupt, so every
`except KeyboardInterrupt` / `finally` that makes Ctrl-C a controlled stop serves all three)
raised in the main thread; the verb stops the arm, switches the servo off, closes its recording
and exits with `StopSignal.exit_code` = 128 + the signal's number (130, 143, 129). systemd,
`timeout`, `docker stop` and `kill` send SIGTERM; a closed terminal sends SIGHUP.

Only the first signal interrupts: a second one while the stop is under way is ignored, so a
repeated Ctrl-C cannot cut the controlled stop short (SIGKILL still can; the bridge's watchdog
then stops the arm).
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class StopSignal(KeyboardInterrupt):
    """A stop requested by a signal (SIGINT, SIGTERM or SIGHUP)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = int(signum)

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name


def exit_code(e: KeyboardInterrupt) -> int:
    """128 + the signal's number; a plain KeyboardInterrupt counts as SIGINT (130)."""
    return 128 + getattr(e, "signum", int(signal.SIGINT))


def signal_name(e: KeyboardInterrupt) -> str:
    """'SIGTERM', 'SIGHUP' or 'SIGINT' (Ctrl-C)."""
    return e.name if isinstance(e, StopSignal) else "SIGINT"


@contextmanager
def stop_on_signals() -> Iterator[None]:
    """Within the block, SIGINT/SIGTERM/SIGHUP raise StopSignal in the main thread (once); the
    previous handlers come back on exit. Outside the main thread it does nothing (Python only
    delivers signals there)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    fired: list[int] = []

    def handler(signum: int, frame: object) -> None:
        if fired:
            return  # already stopping: let the controlled stop finish
        fired.append(signum)
        raise StopSignal(signum)

    old = {s: signal.signal(s, handler) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def report_stop(verb: str, e: KeyboardInterrupt, what: str) -> int:
    """Print the one line of a stopped verb ('photoservo move: interrupted by SIGTERM: controlled
    stop, servo off') and return its exit status, 128 + the signal's number."""
    import sys

    print(f"photoservo {verb}: interrupted by {signal_name(e)}: {what}", file=sys.stderr, flush=True)
    return exit_code(e)
