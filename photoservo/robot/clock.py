"""Fixed-rate loop timing on the monotonic clock (the control loop's 250 Hz cadence).

    rate = Rate(250.0)
    while running:
        ...one control period of work...
        rate.sleep()          # until the next period boundary; returns how late we woke (s)

Periods are kept on a fixed grid (t0 + k·T), so one late wake-up does not shift every later
period; after a stall longer than `max_behind` periods the grid restarts from now instead of
running the missed periods back to back.
"""

from __future__ import annotations

import gc
import os
import signal
import time
from collections import deque


class Rate:
    """Sleep to the next boundary of a fixed period T = 1/hz (monotonic seconds)."""

    def __init__(self, hz: float, max_behind: int = 3) -> None:
        if not hz > 0:
            raise ValueError(f"rate {hz} Hz must be > 0")
        self.T = 1.0 / hz
        self.max_behind = max_behind
        self.t_next = time.monotonic() + self.T
        self.overruns = 0  # periods whose work ended after the next boundary

    def sleep(self) -> float:
        """Sleep until the next period boundary; return the lateness of the wake-up (s, >= 0)."""
        now = time.monotonic()
        if now > self.t_next:
            self.overruns += 1
            if now - self.t_next > self.max_behind * self.T:
                self.t_next = now + self.T
                return 0.0
        else:
            time.sleep(self.t_next - now)
        woke = time.monotonic()
        late = max(0.0, woke - self.t_next)
        self.t_next += self.T
        return late


class WindowMin:
    """The least of the last `n` values added (the link's bridge-clock offset: the least-delayed
    report of the last ~2 s). O(1) amortised per value: a deque of the values that can still be
    the least, increasing from the front; min() over all n cost the link's reader thread ~0.1 ms
    a state report at 250 Hz.

    >>> w = WindowMin(3)
    >>> [w.add(v) for v in (5.0, 3.0, 4.0, 6.0, 7.0)]
    [5.0, 3.0, 3.0, 3.0, 4.0]
    """

    def __init__(self, n: int) -> None:
        if n < 1:
            raise ValueError(f"window of {n} values must hold at least one")
        self.n = n
        self._k = 0  # index of the next value
        self._q: deque[tuple[int, float]] = deque()  # (index, value), values increasing

    def add(self, value: float) -> float:
        """Add `value`; return the least of the last n values."""
        q = self._q
        while q and q[-1][1] >= value:
            q.pop()
        q.append((self._k, value))
        self._k += 1
        if q[0][0] <= self._k - 1 - self.n:
            q.popleft()
        return q[0][1]

    def clear(self) -> None:
        self._k = 0
        self._q.clear()


def set_realtime(priority: int) -> None:
    """Give the calling process SCHED_FIFO real-time priority `priority` (1..99, Linux), so the
    control loop is not starved by other work on the machine. Threads started afterwards inherit
    it, so call it before starting the link. Raises OSError (e.g. EPERM) when not permitted."""
    if not 1 <= priority <= 99:
        raise ValueError(f"real-time priority {priority} is outside 1..99")
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))


def raise_priority(priority: int, nice: int = -10) -> str:
    """Best effort against a busy machine, for the loops that must hold their period (the
    control process, the simulator's bridge): SCHED_FIFO `priority` when permitted, else the
    niceness `nice` when permitted, else unchanged. Threads started afterwards inherit it.
    Returns what was got, for the session's events: 'SCHED_FIFO 20', 'nice -10' or 'normal'."""
    try:
        set_realtime(priority)
        return f"SCHED_FIFO {priority}"
    except (OSError, AttributeError):
        pass
    try:
        os.setpriority(os.PRIO_PROCESS, 0, nice)
        return f"nice {nice}"
    except (OSError, AttributeError):
        return "normal"


def lower_priority(nice: int, keep: set[int] | frozenset[int] = frozenset()) -> str:
    """The other side of `raise_priority` when it got no real-time class: raise the niceness of
    every thread of this process and of its descendant processes to at least `nice` (always
    permitted), except the processes or threads whose ids are in `keep` (a kept process keeps
    its descendants too). The loops that must hold their period (the control process, the
    simulator's bridge) then win the CPU from the work that can wait (vision, the renderer, the
    video encoder). Linux (/proc); returns what was done, for the session's events."""
    threads, procs = 0, 0
    todo = [os.getpid()]
    while todo:
        pid = todo.pop()
        if pid in keep:
            continue
        try:
            tids = [int(t) for t in os.listdir(f"/proc/{pid}/task")]
        except OSError:  # ended meanwhile, or no /proc
            continue
        procs += 1
        for tid in tids:
            try:
                todo += [int(c) for c in open(f"/proc/{pid}/task/{tid}/children").read().split()]
            except OSError:
                pass
            if tid in keep:
                continue
            try:
                if os.getpriority(os.PRIO_PROCESS, tid) < nice:
                    os.setpriority(os.PRIO_PROCESS, tid, nice)
                    threads += 1
            except OSError:
                pass
    return f"nice {nice} for {threads} threads of {procs} processes"


def freeze_heap() -> int:
    """For a loop that must hold its period (the control process; the vision loop too): one full garbage collection
    now, then every object alive moved out of the collector's reach (`gc.freeze`), so that the
    loop's own collections scan only what it allocates since. Without it the first full
    collection after the start (gen 2, over the ~110k objects that numpy, numba and the link
    import) came 1-2 s into a session and took 45-60 ms on this 2-core machine: 12-15 control
    periods without a setpoint, and the bridge's 3-period watchdog stopped the arm. In the vision
    process (~149k objects) they took 65-110 ms, 2-3 frames. Returns the number of objects
    frozen."""
    gc.collect()
    gc.freeze()
    return gc.get_freeze_count()


#: Ctrl-C, SIGTERM, SIGHUP: a terminal, `timeout` or systemd may send them to a whole process group
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def ignore_stop_signals() -> None:
    """In a child process of a session (control loop, renderer, bridge emulator): ignore the stop
    signals; the session process gets them too and stops its children in order (the arm with a
    controlled stop and the servo off first). The parent blocks them while starting the child
    (`start_child`), so none lands before this call."""
    for s in STOP_SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)


def start_child(proc) -> None:
    """`proc.start()` (a multiprocessing Process) with the stop signals blocked: the mask is
    inherited through fork and exec, until the child ignores them itself (`ignore_stop_signals`)."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    try:
        proc.start()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
