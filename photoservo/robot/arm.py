"""The arm as the product loop sees it (DESIGN.md, "Time and frames in the loop"), in the LeRobot
style of one small abstract class per kind of device:

  * `Arm`: what the control tick commands and reads. `robot.link.Link` (the serial bridge of the
    real PA-10, or the emulator on a pty) and `sim.arm.LockstepArm` (the emulator's bridge on the
    simulation's clock) implement it.
  * `JointHistory`: the one place where "the joint state at time t" is interpolated — where the
    cameras were at a frame's capture time (the session's state stream, the lockstep arm, the
    serial link's state reports, a recording's joint samples).

Times are seconds on the caller's clock (the monotonic clock, or the simulation's); joints in
radians, joint velocities in rad/s.
"""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
from bisect import bisect_right
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class ArmState:
    """A joint state: time t (s), positions q (rad), velocities dq (rad/s), the bridge's status
    and fault flags (robot/protocol.py)."""

    t: float
    q: np.ndarray
    dq: np.ndarray
    status: Any
    fault: Any


class Arm(ABC):
    """An arm behind the bridge's wire protocol (docs/protocol.md). Every command may raise
    `robot.link.LinkError` (refused by the bridge, or the bridge gone)."""

    @abstractmethod
    def enable(self) -> None:
        """Servo on: brakes released, holding the measured position."""

    @abstractmethod
    def disable(self) -> None:
        """Servo off: the bridge stops any motion within the limits, then engages the brakes."""

    @abstractmethod
    def stop(self) -> None:
        """Controlled stop: the setpoint stream is dropped and the arm decelerates to rest."""

    @abstractmethod
    def tool(self, on: bool, output: int = 0) -> None:
        """Switch a tool output (0 = the collection net / gripper)."""

    @abstractmethod
    def send_setpoint(self, q: np.ndarray, dq: np.ndarray, t_host: float | None = None) -> int | None:
        """Stream one joint setpoint: positions q (rad) and velocities dq (rad/s), stamped
        t_host (s). Returns its sequence number (None: dropped, the line was busy)."""

    @abstractmethod
    def state(self) -> Any:
        """The latest joint state: an object with t (s), q (rad, (7,)), dq (rad/s, (7,)),
        status and fault."""

    @abstractmethod
    def state_at(self, t: float) -> Any:
        """The joint state at time t (s), interpolated (`JointHistory`). Raises LookupError
        when t lies outside the kept history."""


class JointHistory:
    """Joint states (t, q, dq) in time order; `at(t)` interpolates them linearly.

    Keeps the last `keep_s` seconds. A t after the newest state is allowed by up to `ahead_s`
    (extrapolated with the newest velocity, zero when none was given); a t before the oldest
    kept state, or further ahead, raises LookupError. Appends and reads may come from different
    threads.

    >>> h = JointHistory(keep_s=1.0, ahead_s=0.01)
    >>> h.append(0.0, np.zeros(7)); h.append(0.1, np.full(7, 0.2))
    >>> float(h.at(0.05)[0][0])
    0.1
    """

    def __init__(self, keep_s: float = float("inf"), ahead_s: float = 0.0) -> None:
        self.keep_s, self.ahead_s = keep_s, ahead_s
        self._t: deque[float] = deque()
        self._q: deque[np.ndarray] = deque()
        self._dq: deque[np.ndarray] = deque()
        self._lock = threading.Lock()

    @classmethod
    def from_samples(cls, t: np.ndarray, q: np.ndarray) -> "JointHistory":
        """A recording's joint samples q (N, 7) at times t (N,): duplicate times dropped, dq by
        finite differences (np.gradient)."""
        t, idx = np.unique(np.asarray(t, dtype=np.float64), return_index=True)
        q = np.asarray(q, dtype=np.float64)[idx]
        dq = np.gradient(q, t, axis=0) if len(t) > 1 else np.zeros_like(q)
        h = cls()
        for k in range(len(t)):
            h.append(float(t[k]), q[k], dq[k])
        return h

    def append(self, t: float, q: np.ndarray, dq: np.ndarray | None = None) -> None:
        """Add the state at time t (not older than the newest one)."""
        q = np.asarray(q, dtype=np.float64)
        with self._lock:
            self._t.append(t)
            self._q.append(q)
            self._dq.append(np.zeros_like(q) if dq is None else np.asarray(dq, dtype=np.float64))
            while self._t and self._t[0] < t - self.keep_s:
                self._t.popleft()
                self._q.popleft()
                self._dq.popleft()

    def __len__(self) -> int:
        return len(self._t)

    @property
    def span(self) -> tuple[float, float]:
        """(oldest, newest) time kept (s)."""
        with self._lock:
            return (self._t[0], self._t[-1]) if self._t else (float("nan"), float("nan"))

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(q, dq) at time t: linear interpolation between the two states around it."""
        with self._lock:
            ts = self._t
            if not ts or t < ts[0] or t > ts[-1] + self.ahead_s:
                first = f" (kept: {ts[0]:.4f} .. {ts[-1]:.4f})" if ts else ""
                raise LookupError(f"no joint state around time {t:.4f}{first}")
            if t >= ts[-1]:
                return self._q[-1] + self._dq[-1] * (t - ts[-1]), self._dq[-1].copy()
            i = bisect_right(ts, t)  # ts[i-1] <= t < ts[i]
            a, b = ts[i - 1], ts[i]
            w = 0.0 if b == a else (t - a) / (b - a)
            qa, dqa = self._q[i - 1], self._dq[i - 1]
            return qa + w * (self._q[i] - qa), dqa + w * (self._dq[i] - dqa)
