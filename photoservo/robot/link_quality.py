"""The link-quality gate's bookkeeping (issue 12): bad frames, refused setpoints and bridge
watchdog stops counted over a sliding window, and the test against their configured rates.

Pure: times are host `time.monotonic()` seconds handed in by the caller (robot/link.py, which
counts the events in its reader thread and raises LinkQualityError when `LinkQuality.over`
names a rate past its limit).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from photoservo.robot import protocol as P

#: event kinds (indices into QualityWindow.totals / counts)
BAD, REFUSED, WATCHDOG = 0, 1, 2


@dataclass(frozen=True)
class LinkQuality:
    """Totals since the link opened and rates over the last window_s (events per second).

    bad_frames: frames dropped for a bad CRC/COBS/length/version/type, by the host's decoder
        plus those the bridge reports dropping (StateReport.rx_crc_errors).
    refused: setpoints the bridge refused (NACK: JUMP, STALE, SPEED...).
    watchdog_stops: times the bridge's setpoint watchdog stopped the arm (WATCHDOG bit rising).
    """

    bad_frames: int
    refused: int
    watchdog_stops: int
    window_s: float
    bad_frames_per_s: float
    refused_per_s: float
    watchdog_per_s: float

    def text(self) -> str:
        """Status-line form: 'link ok', or the rates over the window."""
        if not (self.bad_frames_per_s or self.refused_per_s or self.watchdog_per_s):
            return "link ok"
        return (f"link {self.bad_frames_per_s:.0f} bad frames/s, {self.refused_per_s:.0f} refused/s, "
                f"{self.watchdog_per_s:.0f} watchdog stops/s")

    def totals(self) -> str:
        return (f"{self.bad_frames} bad frames, {self.refused} refused setpoints, "
                f"{self.watchdog_stops} watchdog stops")

    def advice(self, max_bad_per_s: float, simulated: bool) -> str:
        """What to do about a tripped gate: a noisy line (bad frames past max_bad_per_s), or
        setpoints late on a clean line (refusals / watchdog stops alone: a starved host)."""
        if self.bad_frames_per_s > max_bad_per_s:
            if simulated:
                return "The simulator's line has faults switched on (pa10-sim --drop/--corrupt)."
            return "The line is noisy: check the cable, its shielding and connectors, and the baud rate."
        return ("The line is clean but setpoints reach the bridge late: the control loop is starved of CPU; "
                "close other programs or run with --rt-priority.")

    def over(self, max_bad_per_s: float, max_refused_per_s: float, max_watchdog_per_s: float) -> str:
        """'' while every rate is within its limit (events per s), else the counts in the window
        that passed, e.g. '37 bad frames (limit 10/s), 4 watchdog stops (limit 3/s)'."""
        rows = ((self.bad_frames_per_s, max_bad_per_s, "bad frames"),
                (self.refused_per_s, max_refused_per_s, "refused setpoints"),
                (self.watchdog_per_s, max_watchdog_per_s, "watchdog stops"))
        return ", ".join(f"{rate * self.window_s:.0f} {what} (limit {lim:g}/s)"
                         for rate, lim, what in rows if rate > lim)


class QualityWindow:
    """Event counts of the three kinds over a sliding window of window_s seconds. Not locked:
    its owner serialises access."""

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self.totals = [0, 0, 0]
        self._events: deque[tuple[float, int, int]] = deque()  # (t, kind, n)

    def add(self, t: float, kind: int, n: int = 1) -> None:
        """`n` events of `kind` (BAD, REFUSED, WATCHDOG) at time t (s)."""
        if n > 0:
            self.totals[kind] += n
            self._events.append((t, kind, n))

    def snapshot(self, now: float) -> LinkQuality:
        """Totals, and rates over (now - window_s, now]."""
        while self._events and self._events[0][0] <= now - self.window_s:
            self._events.popleft()
        c = [0, 0, 0]
        for _, kind, n in self._events:
            c[kind] += n
        w = self.window_s
        return LinkQuality(*self.totals, w, c[BAD] / w, c[REFUSED] / w, c[WATCHDOG] / w)


def report_events(prev: P.StateReport | None, m: P.StateReport) -> tuple[int, int]:
    """(bad frames, watchdog stops) that state report `m` tells of since the previous one
    received: the growth of the bridge's rx_crc_errors counter (wraps at 2^32) and a rising
    WATCHDOG bit. The first report sets the baseline (0, 0)."""
    if prev is None:
        return 0, 0
    bad = (m.rx_crc_errors - prev.rx_crc_errors) & 0xFFFFFFFF
    watchdog = int(bool(m.status & P.Status.WATCHDOG) and not prev.status & P.Status.WATCHDOG)
    return bad, watchdog
