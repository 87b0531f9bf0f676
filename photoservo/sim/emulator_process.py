"""The bridge emulator in its own process, for the simulator's real-time session (issue 12:
the simulator keeps its period under load).

As a thread of the vision process the emulator shared that process's interpreter lock with the
tracker's GA and the status line, and on a busy machine its 250 Hz loop was starved for up to a
quarter of a second: the host saw a silent bridge. In its own process it raises its scheduling
(`raise_priority`: SCHED_FIFO above the control process when permitted, else a negative
niceness) like the dedicated hardware it stands for. The true joint state it publishes after
every tick goes through shared memory with a sequence lock (no lock the real-time writer could
wait on), for the simulated cameras' `true_state()`.

    with EmulatorProcess(cfg.emulator, limits, q0=q0) as emu:   # emu.path: the pty
        ... Link(emu.path, ...) ...  emu.true_state() ...
"""

from __future__ import annotations

import multiprocessing
import time
import numpy as np

from photoservo.robot import protocol as P
from photoservo.robot.arm import ArmState
from photoservo.robot.clock import start_child
from photoservo.robot.pa10 import N_JOINTS, PA10Limits
from photoservo.sim.emulator import Bridge, Emulator, EmulatorParams

#: SCHED_FIFO priority of the emulator process: above the control process's (see servo/realtime.py)
EMULATOR_RT_PRIORITY = 30
_SLOTS = 1 + 1 + 2 * N_JOINTS + 2  # seq, t, q, dq, status, fault


def _publish(shared, t: float, q: np.ndarray, dq: np.ndarray, status: int, fault: int) -> None:
    """Sequence-lock writer: seq odd while writing, even when the slots are whole."""
    shared[0] += 1
    shared[1] = t
    shared[2:2 + N_JOINTS] = q.tolist()
    shared[2 + N_JOINTS:2 + 2 * N_JOINTS] = dq.tolist()
    shared[2 + 2 * N_JOINTS] = status
    shared[3 + 2 * N_JOINTS] = fault
    shared[0] += 1


def _emulator_main(params: EmulatorParams, limits: PA10Limits, q0, shared, conn, stop) -> None:
    from photoservo.robot.clock import ignore_stop_signals, raise_priority

    ignore_stop_signals()  # the session stops it, after the arm

    sched = raise_priority(EMULATOR_RT_PRIORITY, nice=-15)
    emu = Emulator(params, limits, q0=q0)
    emu.on_tick = lambda t, q, dq, status, fault: _publish(shared, t, q, dq, status, fault)
    try:
        path = emu.start()
        s = emu.true_state()
        _publish(shared, s.t, s.q, s.dq, int(s.status), int(s.fault))
        conn.send(("ready", path, sched))
        while not stop.wait(0.1):
            if emu.error is not None:
                break
    finally:
        emu.stop()
        m = emu.model
        conn.send(("done", repr(emu.error) if emu.error else "", {
            "accepted": m.accepted, "refused": m.refused, "refusals": dict(m.refusals), "watchdog_stops": m.watchdog_stops,
            "commands": dict(m.commands),
            "tick_overruns": emu.tick_overruns, "states_skipped": emu.states_skipped, "end": m.describe_end()}))


class EmulatorProcess(Bridge):
    """`Emulator`'s start/stop/true_state/path, run in a spawned process (see the module
    docstring). `scheduling` says what priority it got; `summary` holds its counters after stop()."""

    def __init__(self, params: EmulatorParams, limits: PA10Limits, q0: np.ndarray | None = None) -> None:
        ctx = multiprocessing.get_context("spawn")
        self._shared = ctx.RawArray("d", _SLOTS)
        self._conn, child = ctx.Pipe()
        self._stop = ctx.Event()
        self._proc = ctx.Process(target=_emulator_main, args=(params, limits, q0, self._shared, child, self._stop),
                                 name="photoservo-emulator", daemon=True)
        self.path: str | None = None
        self.scheduling = ""
        self.summary: dict = {}
        self.error = ""

    def start(self, timeout_s: float = 60.0) -> str:
        """Start the process; return the pty path once the bridge runs."""
        start_child(self._proc)
        if not self._conn.poll(timeout_s):
            self._proc.kill()
            raise RuntimeError(f"the simulator's bridge (emulator process) did not start within {timeout_s:g} s")
        _, self.path, self.scheduling = self._conn.recv()
        return self.path

    @property
    def ids(self) -> frozenset[int]:
        pid = self._proc.pid
        return frozenset() if pid is None else frozenset({pid})

    def stop(self) -> None:
        """Stop the bridge (the pty closes) and collect its counters."""
        self._stop.set()
        if self._conn.poll(5.0):
            msg = self._conn.recv()
            if msg[0] == "done":
                _, self.error, self.summary = msg
        self._proc.join(timeout=5.0)
        if self._proc.is_alive():  # it ignores SIGTERM (ignore_stop_signals)
            self._proc.kill()

    def true_state(self) -> ArmState:
        """The emulated arm's joint state at its last tick (copies)."""
        sh = self._shared
        while True:
            seq = sh[0]
            if int(seq) % 2 == 0:
                v = np.array(sh[:], float)
                if sh[0] == seq:
                    break
            time.sleep(0)
        n = N_JOINTS
        return ArmState(float(v[1]), v[2:2 + n].copy(), v[2 + n:2 + 2 * n].copy(),
                         P.Status(int(v[2 + 2 * n])), P.Fault(int(v[3 + 2 * n])))
