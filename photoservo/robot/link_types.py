"""Value objects and errors of the host's serial link to the bridge (robot/link.py): its
[link] parameters, a state report as the host knows it, and the errors a caller catches.

Times are `time.monotonic()` seconds on the host; joints in radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from photoservo.errors import HardwareError, InputError
from photoservo.robot import protocol as P


class LinkError(HardwareError, ConnectionError):
    """The bridge refused a command, went silent, or went away. The message says what to do."""


class LinkQualityError(LinkError):
    """The link-quality gate tripped: too many bad frames, refused setpoints or watchdog stops."""


@dataclass(frozen=True)
class LinkParams:
    """[link] section of configs/default.toml."""

    baud: int
    silence_timeout_s: float
    ack_timeout_s: float
    history_s: float
    quality_window_s: float  # the link-quality gate's window (s)
    max_bad_frames_per_s: float  # bad frames (both directions) per s over the window that stop the arm
    max_refused_per_s: float  # setpoints the bridge refused, per s over the window
    max_watchdog_per_s: float  # bridge watchdog stops, per s over the window

    def validate(self, where: str) -> None:
        w = f"{where}." if where else ""
        if not 0 < self.baud <= 20_000_000:
            raise InputError(f"config key '{w}baud': {self.baud} must be in 1..20000000")
        bounds = {"silence_timeout_s": (0.0, 10.0), "ack_timeout_s": (0.0, 10.0), "history_s": (0.0, 60.0),
                  "quality_window_s": (0.0, 10.0)}
        for k, (lo, hi) in bounds.items():
            v = getattr(self, k)
            if not lo < v <= hi:
                raise InputError(f"config key '{w}{k}': {v} must be in ({lo:g}, {hi:g}]")
        for k in ("max_bad_frames_per_s", "max_refused_per_s", "max_watchdog_per_s"):
            v = getattr(self, k)
            if not 0.0 <= v <= 1000.0:  # finite: inf would switch the gate off
                raise InputError(f"config key '{w}{k}': {v} must be in [0, 1000]")


@dataclass(frozen=True)
class JointState:
    """A state report as the host knows it.

    t: bridge measurement time on the host clock (s): t_bridge mapped by the smallest observed
       receive delay of the last 512 reports (`Link._offsets`), so line and thread-wakeup jitter drop out.
    t_rx: host monotonic time the report was decoded (s).
    q, dq: joint positions (rad) and velocities (rad/s).
    """

    t: float
    t_rx: float
    q: np.ndarray
    dq: np.ndarray
    status: P.Status
    fault: P.Fault
    report: P.StateReport

    @property
    def servo_on(self) -> bool:
        return bool(self.status & P.Status.SERVO_ON)

    @property
    def moving(self) -> bool:
        return bool(self.status & P.Status.MOVING)


def describe_nack(n: P.Nack, names: tuple[str, ...] | None = None) -> str:
    try:
        err = P.Error(n.error).name
    except ValueError:
        err = f"error {n.error}"
    try:
        what = P.MsgType(n.msg_type).name
    except ValueError:
        what = f"type 0x{n.msg_type:02x}"
    where = ""
    if n.joint != 255:
        name = names[n.joint] if names and n.joint < len(names) else f"joint {n.joint + 1}"
        where = f" at {name} (value {n.value:.4g})"
    return f"bridge refused {what}: {err}{where}"
