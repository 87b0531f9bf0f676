"""PA-10 serial-bridge emulator on a pseudo-terminal (issue 3 item 3).

The bridge we would build in firmware, in Python: it opens a pty, speaks the wire protocol
(robot/protocol.py, docs/protocol.md) and moves seven simulated joints toward the host's
setpoints within the joint limits of configs/pa10.toml. Used by the tests, by `photoservo
pa10-sim` and by the tracking simulator (which reads the true joint state with `true_state()`).

Two parts:
- `BridgeModel` — the bridge's behaviour, pure and clocked by the caller (no I/O): message
  handling, setpoint checks (range, speed, one-period jump), the 3-period setpoint watchdog
  (controlled stop), the brake timeout, emergency stop, tool outputs.
- `Emulator` — the I/O edge: pty, byte pacing at a baud rate, fault injection (dropped,
  corrupted, delayed bytes), a thread that ticks the model at the control rate and streams state.

Joints move in radians; times are `time.monotonic()` seconds (the bridge clock, sent in µs).
"""

from __future__ import annotations

import errno
import os
import select
import threading
import time
import tty
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Self

import numpy as np

from photoservo.errors import InputError
from photoservo.robot import protocol as P
from photoservo.robot.pa10 import HOME_Q, PA10Limits, load_limits

FIRMWARE = 0x00010000  # emulator "firmware" 1.0.0


@dataclass(frozen=True)
class EmulatorParams:
    """[emulator] section of configs/default.toml (units in the key names there)."""

    control_hz: float
    state_hz: float
    baud: int
    watchdog_periods: int
    brake_after_s: float
    jump_tolerance: float
    drop: float
    corrupt: float
    delay: float
    delay_ms: float
    seed: int

    def validate(self, where: str) -> None:
        w = f"{where}." if where else ""
        if not 1.0 <= self.control_hz <= 5000.0:
            raise InputError(f"config key '{w}control_hz': {self.control_hz} is outside 1..5000 Hz")
        if not 1.0 <= self.state_hz <= self.control_hz:
            raise InputError(f"config key '{w}state_hz': {self.state_hz} must be in 1..control_hz")
        if self.baud < 0:
            raise InputError(f"config key '{w}baud': {self.baud} must be >= 0 (0 = unpaced)")
        if not 1 <= self.watchdog_periods <= 255:
            raise InputError(f"config key '{w}watchdog_periods': {self.watchdog_periods} is outside 1..255")
        if self.brake_after_s <= self.watchdog_periods / self.control_hz:
            raise InputError(f"config key '{w}brake_after_s': {self.brake_after_s} must exceed the watchdog time")
        if not 0.0 <= self.jump_tolerance <= 1.0:
            raise InputError(f"config key '{w}jump_tolerance': {self.jump_tolerance} is outside 0..1")
        for k in ("drop", "corrupt", "delay"):
            if not 0.0 <= getattr(self, k) <= 1.0:
                raise InputError(f"config key '{w}{k}': {getattr(self, k)} is not a probability in 0..1")
        if self.delay_ms < 0:
            raise InputError(f"config key '{w}delay_ms': {self.delay_ms} must be >= 0")


# ----------------------------------------------------------------------------- the bridge


class BridgeModel:
    """The bridge's behaviour, clocked by the caller: `handle(frame, now)` for each valid frame
    received, `tick(now)` once per control period T, `report(now)` for the state message.

    Joint servo (one tick, per joint, T = control period, a = ddq_max): velocity feed-forward
    plus a time-optimal correction of what it leaves over, then acceleration-limited:
        e  = q_sp - q - dq_sp·T
        v* = clip(dq_sp + sign(e)·min(|e|/T, sqrt(2·a·|e|)), ±dq_max)
        dq <- dq + clip(v* - dq, ±a·T);   q <- q + (mean of old and new dq)·T
    Setpoint checks, in order: servo on and not stopping, finite, newer seq, inside
    [q_min, q_max], |dq_sp| <= dq_max, and |q_sp - q_ref| <= dq_max·T·k·(1 + jump_tolerance),
    q_ref the last accepted setpoint (the measured q for the first one), k = the periods since
    it, between 1 and watchdog_periods (so one lost frame does not cascade into refusals).
    """

    def __init__(self, limits: PA10Limits, params: EmulatorParams, q0: np.ndarray | None = None,
                 now: float = 0.0) -> None:
        self.limits = limits
        self.q_min = np.asarray(limits.q_min, float)
        self.q_max = np.asarray(limits.q_max, float)
        self.dq_max = np.asarray(limits.dq_max, float)
        self.ddq_max = np.asarray(limits.ddq_max, float)
        self.T = 1.0 / params.control_hz
        self.params = params
        self.q = np.array(HOME_Q if q0 is None else q0, float)
        self.dq = np.zeros_like(self.q)
        self.servo_on = False
        self.braked = True
        self.stopping = False
        self.disable_when_stopped = False
        self.watchdog_fired = False
        self.fault = P.Fault.NONE
        self.tools = [False, False]
        self.q_sp: np.ndarray | None = None  # active setpoint (None: holding / stopping)
        self.dq_sp = np.zeros_like(self.q)
        self.q_ref: np.ndarray | None = None  # last accepted setpoint (jump reference)
        self.t_last_setpoint = now  # last accepted setpoint, or servo enable
        self.t_host_echo_us = 0
        self.last_seq = 0
        self.setpoint_seq: int | None = None
        self.accepted = 0
        self.refused = 0
        self.refusals: dict[str, int] = {}  # refused setpoints by NACK error name
        self.watchdog_stops = 0  # controlled stops for want of setpoints
        self.rx_crc_errors = 0
        self.t_tick = now  # bridge time of the last tick: when q, dq were "measured"

    # -- messages
    def handle(self, frame: P.Frame, now: float) -> list[P.Message]:
        """Carry out one valid frame; return the replies (VERSION, ACK or NACK; nothing for an
        accepted setpoint)."""
        m, seq = frame.msg, frame.seq
        self.last_seq = seq
        ack = [P.Ack(seq, int(m.TYPE))]
        if isinstance(m, P.Hello):
            return [self.version_info()]
        if isinstance(m, P.JointSetpoint):
            err = self._check_setpoint(m, seq, now)
            if err is not None:
                self.refused += 1
                code, joint, value = err
                self.refusals[code.name] = self.refusals.get(code.name, 0) + 1
                return [P.Nack(seq, int(m.TYPE), int(code), joint, value)]
            self.accepted += 1
            self.q_sp = np.array(m.q, float)
            self.dq_sp = np.array(m.dq, float)
            self.q_ref = self.q_sp
            self.t_last_setpoint = now
            self.t_host_echo_us = m.t_host_us
            self.setpoint_seq = seq
            self.watchdog_fired = False
            return []
        if isinstance(m, P.Servo):
            if m.enable:
                if self.fault in (P.Fault.ESTOP, P.Fault.LIMIT, P.Fault.INTERNAL):
                    return [P.Nack(seq, int(m.TYPE), int(P.Error.FAULT_LATCHED))]
                if not self.servo_on:
                    self.servo_on, self.braked = True, False
                    self.fault = P.Fault.NONE
                    self.q_sp, self.q_ref = None, None
                    self.stopping = self.disable_when_stopped = False
                    self.t_last_setpoint = now
                return ack
            if self.servo_on:
                self._begin_stop(disable=True)
            return ack
        if isinstance(m, P.Stop):
            if self.servo_on:
                self._begin_stop(disable=False)
            return ack
        if isinstance(m, P.EStop):
            self._brake(P.Fault.ESTOP)
            return ack
        if isinstance(m, P.ClearFault):
            if not self.servo_on:
                self.fault = P.Fault.NONE
            return ack
        if isinstance(m, P.Tool):
            if m.output not in (0, 1):
                return [P.Nack(seq, int(m.TYPE), int(P.Error.BAD_VALUE), 255, float(m.output))]
            self.tools[m.output] = bool(m.on)
            return ack
        # VERSION, STATE, ACK, NACK are bridge -> host only
        return [P.Nack(seq, int(m.TYPE), int(P.Error.UNKNOWN_TYPE))]

    def _check_setpoint(self, m: P.JointSetpoint, seq: int, now: float):
        if not self.servo_on or self.stopping:
            return P.Error.SERVO_OFF, 255, 0.0
        q, dq = np.array(m.q, float), np.array(m.dq, float)
        bad = ~(np.isfinite(q) & np.isfinite(dq))
        if bad.any():
            return P.Error.NOT_FINITE, int(np.argmax(bad)), 0.0
        if self.setpoint_seq is not None and self.q_ref is not None:
            d = (seq - self.setpoint_seq) & 0xFFFF
            if d == 0 or d >= 0x8000:
                return P.Error.STALE, 255, float(seq)
        out = (q < self.q_min) | (q > self.q_max)
        if out.any():
            j = int(np.argmax(out))
            return P.Error.OUT_OF_RANGE, j, float(q[j])
        tol = 1.0 + self.params.jump_tolerance
        fast = np.abs(dq) > self.dq_max * tol
        if fast.any():
            j = int(np.argmax(fast))
            return P.Error.SPEED, j, float(dq[j])
        q_ref = self.q if self.q_ref is None else self.q_ref
        k = 1.0 if self.q_ref is None else min(max(1.0, (now - self.t_last_setpoint) / self.T),
                                               float(self.params.watchdog_periods))
        jump = np.abs(q - q_ref) > self.dq_max * self.T * k * tol + 1e-6
        if jump.any():
            j = int(np.argmax(jump))
            return P.Error.JUMP, j, float(q[j] - q_ref[j])
        return None

    def _begin_stop(self, disable: bool) -> None:
        self.q_sp, self.q_ref = None, None
        self.stopping = True
        self.disable_when_stopped = self.disable_when_stopped or disable

    def _brake(self, fault: P.Fault) -> None:
        self.dq[:] = 0.0
        self.servo_on, self.braked, self.stopping = False, True, False
        self.disable_when_stopped = False
        self.q_sp, self.q_ref = None, None
        if fault != P.Fault.NONE:
            self.fault = fault

    # -- time
    def tick(self, now: float) -> None:
        """Advance the joints by one control period T (watchdog, brake timeout, servo)."""
        T = self.T
        self.t_tick = now
        if self.servo_on:
            silence = now - self.t_last_setpoint
            if self.q_sp is not None and silence > self.params.watchdog_periods * T:
                self.watchdog_fired = True
                self.watchdog_stops += 1
                self._begin_stop(disable=False)
            if silence > self.params.brake_after_s:
                self._brake(P.Fault.SILENCE)
        if not self.servo_on:
            self.dq[:] = 0.0
            return
        a_max = self.ddq_max * T
        if self.q_sp is not None:
            e = self.q_sp - self.q - self.dq_sp * T  # what the feed-forward velocity leaves over
            v_corr = np.sign(e) * np.minimum(np.abs(e) / T, np.sqrt(2.0 * self.ddq_max * np.abs(e)))
            v_star = np.clip(self.dq_sp + v_corr, -self.dq_max, self.dq_max)
        else:  # holding or stopping: decelerate to rest within ddq_max
            v_star = np.zeros_like(self.dq)
        dq_new = self.dq + np.clip(v_star - self.dq, -a_max, a_max)
        q_new = self.q + 0.5 * (self.dq + dq_new) * T
        self.dq = dq_new
        hit = (q_new < self.q_min) | (q_new > self.q_max)
        self.q = np.clip(q_new, self.q_min, self.q_max)
        if hit.any():
            self._brake(P.Fault.LIMIT)
            return
        if self.stopping and not np.any(self.dq):
            self.stopping = False
            if self.disable_when_stopped:
                self._brake(P.Fault.NONE)

    def status(self) -> P.Status:
        s = P.Status(0)
        if self.servo_on:
            s |= P.Status.SERVO_ON
        if np.any(np.abs(self.dq) > 1e-4):
            s |= P.Status.MOVING
        if self.q_sp is not None:
            s |= P.Status.TRACKING
        if self.stopping:
            s |= P.Status.STOPPING
        if self.braked:
            s |= P.Status.BRAKED
        if self.watchdog_fired:
            s |= P.Status.WATCHDOG
        if self.fault == P.Fault.ESTOP:
            s |= P.Status.ESTOP
        if self.fault in (P.Fault.ESTOP, P.Fault.LIMIT, P.Fault.INTERNAL):
            s |= P.Status.FAULT
        if self.tools[0]:
            s |= P.Status.TOOL0
        if self.tools[1]:
            s |= P.Status.TOOL1
        return s

    def report(self) -> P.StateReport:
        """The state report for the last tick (stamped with that tick's time)."""
        return P.StateReport(
            t_bridge_us=int(self.t_tick * 1e6), t_host_echo_us=self.t_host_echo_us,
            last_seq=self.last_seq, setpoint_seq=self.setpoint_seq or 0,
            status=int(self.status()), fault=int(self.fault),
            rx_crc_errors=self.rx_crc_errors & 0xFFFFFFFF,
            q=tuple(self.q.tolist()), dq=tuple(self.dq.tolist()))

    def version_info(self) -> P.VersionInfo:
        return P.VersionInfo(
            firmware=FIRMWARE, n_joints=P.N_JOINTS,
            control_period_us=round(self.T * 1e6),
            state_period_us=round(1e6 / self.params.state_hz),
            watchdog_periods=self.params.watchdog_periods,
            brake_after_ms=round(self.params.brake_after_s * 1000),
            q_min=tuple(self.q_min.tolist()), q_max=tuple(self.q_max.tolist()),
            dq_max=tuple(self.dq_max.tolist()))


# ----------------------------------------------------------------------------- the line


class FaultInjector:
    """One direction of a faulty line: each byte is dropped with probability `drop`, has a
    random bit pattern XORed in with probability `corrupt`, and with probability `delay` stalls
    the stream (that byte and all after it) by `delay_ms`. Order is always kept."""

    def __init__(self, drop: float, corrupt: float, delay: float, delay_ms: float,
                 rng: np.random.Generator) -> None:
        self.drop, self.corrupt, self.delay, self.delay_s = drop, corrupt, delay, delay_ms / 1000
        self.rng = rng
        self._queue: deque[tuple[float, bytes]] = deque()
        self._last_release = 0.0
        self.dropped = self.corrupted = self.delays = 0

    @property
    def active(self) -> bool:
        return bool(self.drop or self.corrupt or self.delay)

    def push(self, data: bytes, now: float) -> None:
        if not data:
            return
        if not self.active:
            self._queue.append((max(now, self._last_release), data))
            return
        a = np.frombuffer(data, np.uint8).copy()
        u = self.rng.random((3, a.size))
        flip = u[1] < self.corrupt
        if flip.any():
            a[flip] ^= self.rng.integers(1, 256, int(flip.sum()), dtype=np.uint8)
            self.corrupted += int(flip.sum())
        stall = u[2] < self.delay
        keep = u[0] >= self.drop
        self.dropped += int((~keep).sum())
        cuts = np.flatnonzero(stall)
        release = max(now, self._last_release)
        start = 0
        for c in list(cuts) + [a.size]:
            part = a[start:c][keep[start:c]].tobytes()
            if part:
                self._queue.append((release, part))
            if c < a.size:
                self.delays += 1
                release += self.delay_s
            start = c
        self._last_release = release

    def pop(self, now: float) -> bytes:
        out = bytearray()
        while self._queue and self._queue[0][0] <= now:
            out += self._queue.popleft()[1]
        return bytes(out)

    def queued_bytes(self) -> int:
        """Bytes accepted by push() and not yet released by pop()."""
        return sum(len(b) for _, b in self._queue)

    def next_release(self) -> float | None:
        return self._queue[0][0] if self._queue else None


class _Pacer:
    """Token bucket: bytes may pass at baud/10 per second (8N1). Unused capacity is kept up to
    `burst` bytes (a UART FIFO / DMA buffer), so a loop that wakes late does not lose line time."""

    def __init__(self, baud: int, burst: int = 256) -> None:
        self.rate = baud / 10.0
        self.burst = burst
        self.tokens = float(burst)
        self.t = time.monotonic()

    def allow(self, now: float) -> int:
        if self.rate <= 0:
            return 1 << 16
        self.tokens = min(self.burst, self.tokens + (now - self.t) * self.rate)
        self.t = now
        return int(self.tokens)

    def spend(self, n: int) -> None:
        if self.rate > 0:
            self.tokens -= n

    def wait_for(self, n: int) -> float:
        """Seconds until `n` bytes may pass."""
        if self.rate <= 0:
            return 0.0
        return max(0.0, (min(n, self.burst) - self.tokens) / self.rate)


@dataclass(frozen=True)
class TrueState:
    """The emulated arm's true joint state (rad, rad/s) at bridge time `t` (monotonic s)."""

    t: float
    q: np.ndarray
    dq: np.ndarray
    status: P.Status
    fault: P.Fault


class Emulator:
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

    def stop(self) -> None:
        """Stop the thread and close the pty (the host sees the bridge go away)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self._close_pty()
        if self.link is not None and self.link.is_symlink():
            self.link.unlink()

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

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

    def true_state(self) -> TrueState:
        """The simulated arm's joint state now (copies)."""
        with self._lock:
            m = self.model
            return TrueState(time.monotonic(), m.q.copy(), m.dq.copy(), m.status(), P.Fault(m.fault))

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
        p = self.params
        T = 1.0 / p.control_hz
        state_every = max(1, round(p.control_hz / p.state_hz))
        rx_pace, tx_pace = _Pacer(p.baud), _Pacer(p.baud)
        tx_buf = bytearray()
        master = self._master
        next_tick = time.monotonic() + T
        n_tick = 0
        frame_len = len(P.encode(self.model.report(), 0))
        while not self._stop.is_set():
            now = time.monotonic()
            silent = self._silent.is_set()
            rx_throttled = False
            # receive: read only what the line could have carried (the rest stays in the pty)
            if not silent:
                n = rx_pace.allow(now)
                if n > 0:
                    try:
                        data = os.read(master, n)
                    except BlockingIOError:
                        data = b""
                    except OSError as e:
                        if e.errno == errno.EIO:  # nobody has the slave open (not possible: we hold it)
                            data = b""
                        else:
                            raise
                    rx_pace.spend(len(data))
                    rx_throttled = rx_pace.rate > 0 and len(data) == n
                    self.rx_faults.push(data, now)
                got = self.rx_faults.pop(now)
                if got:
                    with self._lock:
                        for frame in self.decoder.iter_feed(got):
                            for reply in self.model.handle(frame, now):
                                self._send(reply, now)
                        self.model.rx_crc_errors = self.decoder.errors
            # control tick(s)
            if now >= next_tick:
                with self._lock:
                    self.model.tick(next_tick)
                    n_tick += 1
                    if n_tick % state_every == 0 and not silent:
                        if len(tx_buf) + self.tx_faults.queued_bytes() > frame_len:
                            self.states_skipped += 1  # line still busy with the last one
                        else:
                            self._send(self.model.report(), now)
                            self.states_sent += 1
                next_tick += T
                if now - next_tick > 5 * T:  # fell far behind (machine stalled): do not burst
                    self.tick_overruns += 1
                    next_tick = now + T
            # transmit, paced
            tx_buf += self.tx_faults.pop(now)
            if silent:
                tx_buf.clear()
            if tx_buf:
                n = min(tx_pace.allow(now), len(tx_buf))
                if n > 0:
                    try:
                        w = os.write(master, bytes(tx_buf[:n]))
                    except BlockingIOError:
                        w = 0
                    tx_pace.spend(w)
                    del tx_buf[:w]
            # wait: for the next tick, a byte from the host, or the line to free up
            now = time.monotonic()
            timeout = next_tick - now
            if tx_buf:
                timeout = min(timeout, max(tx_pace.wait_for(len(tx_buf)), 2e-4))
            for q in (self.rx_faults, self.tx_faults):
                r = q.next_release()
                if r is not None:
                    timeout = min(timeout, r - now)
            if rx_throttled:  # more may be waiting: come back when the line has carried some
                timeout = min(timeout, max(rx_pace.wait_for(16), 2e-4))
            timeout = max(0.0, timeout)
            if silent or rx_throttled:
                time.sleep(min(timeout, 0.005))
            else:
                select.select([master], [], [], timeout)
