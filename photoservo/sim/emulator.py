"""PA-10 serial-bridge emulator on a pseudo-terminal (issue 3 item 3).

The bridge we would build in firmware, in Python: it opens a pty, speaks the wire protocol
(robot/protocol.py, docs/protocol.md) and moves seven simulated joints toward the host's
setpoints within the joint limits of configs/pa10.toml. Used by the tests, by `photoservo
pa10-sim` and by the tracking simulator (which reads the true joint state with `true_state()`).

Two parts:
- `BridgeModel` (sim/bridge.py) — the bridge's behaviour, pure and clocked by the caller (no I/O): message
  handling, setpoint checks (range, speed, one-period jump), the 3-period setpoint watchdog
  (controlled stop), the brake timeout, emergency stop, tool outputs.
- `Emulator` — the I/O edge: pty, byte pacing at a baud rate and fault injection (dropped,
  corrupted, delayed bytes; sim/line.py), a thread that ticks the model at the control rate and
  streams state. sim/emulator_process.py runs it in a process of its own.

Joints move in radians; times are `time.monotonic()` seconds (the bridge clock, sent in µs).
"""

from __future__ import annotations

import errno
import os
import select
import threading
import time
import tty
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Callable, Self

import numpy as np

from photoservo.errors import InputError
from photoservo.robot import protocol as P
from photoservo.robot.arm import ArmState
from photoservo.robot.pa10 import PA10Limits, load_limits
from photoservo.sim.bridge import FIRMWARE, BridgeModel, EmulatorParams  # noqa: F401 - the emulator's API
from photoservo.sim.line import FaultInjector, Pacer


class Bridge(ABC):
    """What runs a bridge for a session: `start()` (returns the pty path), `stop()`, a context
    manager around the two, and `true_state()`: the emulated arm's true joint state (an
    ArmState: rad, rad/s at bridge time t, monotonic s) for the simulated cameras."""

    @abstractmethod
    def start(self) -> str: ...

    @abstractmethod
    def stop(self) -> None: ...

    @abstractmethod
    def true_state(self) -> ArmState: ...

    @property
    @abstractmethod
    def ids(self) -> frozenset[int]:
        """The process or thread ids that run the bridge (a session leaves their priority)."""

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


class Emulator(Bridge):
    """The bridge on a pty, run in a thread.

        emu = Emulator(params)            # limits from configs/pa10.toml, arm at HOME_Q
        path = emu.start()                # '/dev/pts/N' (and `link` symlinked to it)
        ... Link(path) ...
        emu.stop()                        # closes the pty: the bridge "disappears"

    `silence(True)` makes the bridge stop talking (and listening) while the pty stays open,
    to test the host's silence detection. `true_state()` is the simulated arm's joint state for
    the tracking simulator. Counters: `decoder` (CRC failures etc. seen by the bridge),
    `model.accepted` / `model.refused` setpoints, `states_sent`, `states_skipped` (line busy).
    """

    def __init__(self, params: EmulatorParams, limits: PA10Limits | None = None,
                 q0: np.ndarray | None = None, link: str | os.PathLike | None = None) -> None:
        self.params = params
        self.limits = limits if limits is not None else load_limits()
        self.link = Path(link) if link is not None else None
        self.model = BridgeModel(self.limits, params, q0, time.monotonic())
        self.decoder = P.Decoder()
        rng = np.random.default_rng(params.seed)
        self.rx_faults = FaultInjector(params.drop, params.corrupt, params.delay, params.delay_ms, rng)
        self.tx_faults = FaultInjector(params.drop, params.corrupt, params.delay, params.delay_ms, rng)
        self.states_sent = 0
        self.states_skipped = 0
        self.tick_overruns = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._silent = threading.Event()
        self._thread: threading.Thread | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self._seq = 0
        self.path: str | None = None
        self.error: BaseException | None = None
        #: called after every control tick with (bridge time, q, dq, status, fault), under the
        #: model's lock: the emulator process publishes the true state through it
        self.on_tick: Callable[[float, np.ndarray, np.ndarray, int, int], None] | None = None

    # -- lifecycle
    def start(self) -> str:
        """Open the pty, start the bridge thread; return the device path to give the host."""
        if self._thread is not None:
            raise RuntimeError("emulator already started")
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.path = os.ttyname(slave)
        if self.link is not None:
            if self.link.is_symlink() or self.link.exists():
                if not self.link.is_symlink():
                    self._close_pty()
                    raise InputError(f"{self.link}: exists and is not a symlink; not replacing it")
                self.link.unlink()
            try:
                self.link.symlink_to(self.path)
            except OSError as e:
                self._close_pty()
                raise InputError(f"{self.link}: cannot create symlink ({e.strerror or e})") from None
        self._thread = threading.Thread(target=self._run, name="pa10-emulator", daemon=True)
        self._thread.start()
        return self.path

    @property
    def ids(self) -> frozenset[int]:
        t = self._thread
        return frozenset() if t is None or t.native_id is None else frozenset({t.native_id})

    def stop(self) -> None:
        """Stop the thread and close the pty (the host sees the bridge go away)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self._close_pty()
        if self.link is not None and self.link.is_symlink():
            self.link.unlink()

    def silence(self, on: bool = True) -> None:
        """Stop (or resume) all traffic while keeping the pty open: a bridge that hangs."""
        if on:
            self._silent.set()
        else:
            self._silent.clear()

    def line_faults(self, drop: float, corrupt: float, delay: float = 0.0) -> None:
        """Change the fault injection of both directions while running (probabilities per byte,
        as the [emulator] keys): a line that turns noisy mid-move."""
        for f in (self.rx_faults, self.tx_faults):
            f.drop, f.corrupt, f.delay = drop, corrupt, delay

    def true_state(self) -> ArmState:
        """The simulated arm's joint state now (copies)."""
        with self._lock:
            m = self.model
            return ArmState(time.monotonic(), m.q.copy(), m.dq.copy(), m.status(), P.Fault(m.fault))

    def _close_pty(self) -> None:
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None

    # -- the loop
    def _send(self, msg: P.Message, now: float) -> None:
        self._seq = (self._seq + 1) & 0xFFFF
        self.tx_faults.push(P.encode(msg, self._seq), now)

    def _run(self) -> None:
        try:
            self._loop()
        except BaseException as e:  # noqa: BLE001 - recorded for the owner, thread ends
            self.error = e

    def _loop(self) -> None:
        """Until stopped: take the host's bytes (paced), tick the model at the control rate and
        stream its state, send the replies (paced), then wait for whatever comes first."""
        p = self.params
        self._T = 1.0 / p.control_hz
        self._state_every = max(1, round(p.control_hz / p.state_hz))
        # the host's bytes: what the line carried while this thread could not read (the pty
        # holds them) is read at once when it can, up to a brake timeout's worth (see _receive)
        self._rx_pace = Pacer(p.baud, burst=max(256, round(p.baud / 10.0 * p.brake_after_s)))
        self._tx_pace = Pacer(p.baud)
        self._t_rx = 0.0  # when the last frame from the host came off the line (bridge clock)
        self._tx_buf = bytearray()
        self._tx_full = False  # the last write found the pty full (a host not reading: wait, do not poll)
        self._next_tick = time.monotonic() + self._T
        self._n_tick = 0
        self._report_due = False  # ticks ran since the last state report, one of them a state period's
        self._frame_len = len(P.encode(self.model.report(), 0))
        self._fd = self._master  # the pty as the loop started (stop() closes it after the loop)
        while not self._stop.is_set():
            now = time.monotonic()
            silent = self._silent.is_set()
            rx_throttled = False if silent else self._receive(now, silent)
            if now >= self._next_tick or self._report_due:
                self._tick(now, silent)
            self._transmit(now, silent)
            self._wait(rx_throttled, silent)

    def _receive(self, now: float, silent: bool = False) -> bool:
        """Read only what the line could have carried (the rest stays in the pty), through the
        fault injector, into the model. True when the line's rate limited the read.

        Each frame is handled when it came off the line (`_arrival`), after the control ticks
        due before then: when this thread could not read for a while (its process not
        scheduled, or blocked in the pty's read, which waits for the kernel's non-real-time
        worker that moves the host's bytes across), the setpoints the host sent meanwhile are
        taken in their order and at their times, as the bridge it stands for would have taken
        them, instead of all at once at the end (where the ticks before them saw a silent host:
        the watchdog's stop, and the arm behind the host's plan, which re-planned into refusals)."""
        n = self._rx_pace.allow(now)
        throttled = False
        t_read = now
        if n > 0:
            try:
                data = os.read(self._fd, n)
            except BlockingIOError:
                data = b""
            except OSError as e:
                if e.errno != errno.EIO:  # EIO: nobody has the slave open (not possible: we hold it)
                    raise
                data = b""
            t_read = time.monotonic()  # a read may have waited for the pty: the bytes were there by now
            self._rx_pace.spend(len(data))
            throttled = self._rx_pace.rate > 0 and len(data) == n
            self.rx_faults.push(data, t_read)
        got = self.rx_faults.pop(t_read)
        if got:
            for frame in self.decoder.iter_feed(got):
                t = self._arrival(frame, t_read)
                if t >= self._next_tick:
                    self._tick(t, silent, report=False)
                with self._lock:
                    for reply in self.model.handle(frame, t):
                        self._send(reply, t)
            with self._lock:
                self.model.rx_crc_errors = self.decoder.errors
        return throttled

    def _arrival(self, frame: P.Frame, t_read: float) -> float:
        """When a frame read at t_read came off the line (bridge clock): a setpoint at the host's
        stamp (the host and this emulator share the machine's monotonic clock), other frames at
        t_read; never before the frame before it or the last tick run (that tick went without
        it), never after t_read. So only the ticks this thread could not run in time see the
        host's stamps: a host that stalled left a gap in them (the watchdog fires there), a
        stamp from the future counts as t_read, an old one as the last tick. With injected line
        faults (`rx_faults` active: stalls) every frame counts as read when released."""
        t = t_read
        if isinstance(frame.msg, P.JointSetpoint) and not self.rx_faults.active:
            t = min(t_read, max(frame.msg.t_host_us * 1e-6, self._t_rx, self.model.t_tick))
        self._t_rx = t
        return t

    def _tick(self, now: float, silent: bool, report: bool = True) -> None:
        """The control ticks of the model due by `now` (each published through on_tick); then,
        when `report` and a state period ended among the ticks run since the last report, a state
        report, unless the line is still busy with the last one (`_receive` runs the ticks due
        before each frame it takes without one: the loop's call after it reports).

        When this thread fell behind (the simulator's process was not scheduled), the missed
        ticks still move the arm: a real arm does not pause while its bridge's emulator waits for
        the CPU. They run back to back, each on the setpoint the host had sent by its time
        (`_receive`), and one state report follows, not a burst. Only a stall longer than the
        brake timeout is skipped (counted in tick_overruns)."""
        T = self._T
        with self._lock:
            m = self.model
            behind = int((now - self._next_tick) / T)
            if behind > self.params.brake_after_s / T:
                self.tick_overruns += 1
                self._next_tick += behind * T
            n = 0
            while self._next_tick <= now:
                m.tick(self._next_tick)
                if self.on_tick is not None:
                    self.on_tick(self._next_tick, m.q, m.dq, int(m.status()), int(m.fault))
                self._next_tick += T
                self._n_tick += 1
                n += 1
                self._report_due = self._report_due or self._n_tick % self._state_every == 0
            self._report_due = self._report_due or n > 1  # late: report at once
            if report and self._report_due:
                self._report_due = False
                if silent:
                    pass
                elif len(self._tx_buf) + self.tx_faults.queued_bytes() > self._frame_len:
                    self.states_skipped += 1
                else:
                    self._send(m.report(), now)
                    self.states_sent += 1

    def _transmit(self, now: float, silent: bool) -> None:
        """Write what the line can carry now of the queued replies and reports."""
        self._tx_buf += self.tx_faults.pop(now)
        if silent:
            self._tx_buf.clear()
        if self._tx_buf:
            n = min(self._tx_pace.allow(now), len(self._tx_buf))
            if n > 0:
                try:
                    w = os.write(self._fd, bytes(self._tx_buf[:n]))
                except BlockingIOError:
                    w = 0
                self._tx_full = w < n  # the pty holds no more: the host is not reading (yet)
                self._tx_pace.spend(w)
                del self._tx_buf[:w]

    def _wait(self, rx_throttled: bool, silent: bool) -> None:
        """Sleep until the next tick, a byte from the host, a delayed byte's release or the
        line freeing up, whichever comes first."""
        now = time.monotonic()
        timeout = self._next_tick - now
        if self._tx_buf and not self._tx_full:  # a full pty: select wakes when the host has read some
            timeout = min(timeout, max(self._tx_pace.wait_for(len(self._tx_buf)), 2e-4))
        for q in (self.rx_faults, self.tx_faults):
            r = q.next_release()
            if r is not None:
                timeout = min(timeout, r - now)
        if rx_throttled:  # more may be waiting: come back when the line has carried some
            timeout = min(timeout, max(self._rx_pace.wait_for(16), 2e-4))
        timeout = max(0.0, timeout)
        if silent or rx_throttled:
            time.sleep(min(timeout, 0.005))
        else:
            select.select([self._fd], [self._fd] if self._tx_full and self._tx_buf else [], [], timeout)
