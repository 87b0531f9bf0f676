"""Host side of the serial bridge (issue 3 item 4): a pyserial client for the wire protocol.

    with Link("/dev/ttyUSB0", params) as link:        # or any pyserial URL, or a pty path
        link.enable()
        s = link.state()                              # latest StateReport + receive time
        link.send_setpoint(q, dq)                     # never blocks the control loop
        past = link.state_at(t_capture)               # joints where the cameras were then
        link.stop(); link.disable()

A reader thread decodes what the bridge sends and keeps the recent states; a setpoint that
finds the line busy (by the baud rate, see `Link`) is dropped and counted. Control messages
(enable, stop, tool...) wait for their ACK. A bridge silent for `silence_timeout_s` or gone
makes the next call raise `LinkError` saying what to check. The link-quality gate
(robot/link_quality.py): past the [link] max_*_per_s rates of bad frames, refused setpoints or
watchdog stops, `state()` / `send_setpoint()` raise `LinkQualityError` with the counts while
stop and servo off still go out; `quality()` gives the numbers for a status line. Leaving the
`with` block makes a controlled stop and servo off (`safe_stop`); there is no __del__.

Times are `time.monotonic()` seconds on the host; joints in radians.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from typing import Self

import numpy as np
import serial

from photoservo.robot import protocol as P
from photoservo.robot.arm import Arm, JointHistory
from photoservo.robot.clock import WindowMin
from photoservo.robot.link_quality import BAD, REFUSED, WATCHDOG, LinkQuality, QualityWindow, report_events
from photoservo.robot.link_types import JointState, LinkError, LinkParams, LinkQualityError, describe_nack  # noqa: F401
from photoservo.robot.pa10 import fk


class Link(Arm):
    """Serial client of the bridge (life cycle: the module docstring). Setpoints are paced by
    the line's baud rate (`params.baud`): a setpoint is dropped (and counted) while more than
    MAX_BACKLOG_FRAMES setpoints' worth of bytes are still due on the line, because the OS
    would queue it behind them — a pty or a USB adapter buffers kilobytes, i.e. hundreds of
    milliseconds of stale setpoints at 115200 baud. Control messages are always sent.

    Args:
        port: device path (/dev/ttyUSB0, /dev/pts/N) or pyserial URL (socket://, rfc2217://...).
        params: LinkParams (baud for real ports; timeouts; how much state history to keep).
        joint_names: for error messages (default J1..J7).
    """

    MAX_BACKLOG_FRAMES = 1.5

    def __init__(self, port: str, params: LinkParams, joint_names: tuple[str, ...] | None = None,
                 simulated: bool = False) -> None:
        self.port = port
        self.params = params
        self.simulated = simulated  # the bridge is the emulator: errors speak of the simulator
        self.joint_names = joint_names or tuple(f"J{i + 1}" for i in range(P.N_JOINTS))
        self.decoder = P.Decoder()
        self.version: P.VersionInfo | None = None
        self.setpoints_sent = 0
        self.setpoints_dropped = 0
        self.setpoints_held = 0  # not sent: the bridge was making a controlled stop
        self.nacks: deque[P.Nack] = deque(maxlen=64)  # the last 64 NACKs
        self.refused = 0  # setpoints the bridge refused (NACK), all of them
        self._ser: serial.SerialBase | None = None
        self._seq = 0
        self._tx_lock = threading.Lock()
        self._tx_pending = b""
        self._cond = threading.Condition()
        self._replies: dict[int, P.Message] = {}
        self._history: deque[JointState] = deque()
        self._joints = JointHistory(params.history_s)  # the same states, for state_at
        # host = bridge + offset, the offset the least (t_rx - t_bridge) of the last 512 reports
        # (the least-delayed one; the ~2 s window follows slow drift)
        self._offsets = WindowMin(512)
        self._error: LinkError | None = None
        self._quality = QualityWindow(params.quality_window_s)
        self._quality_error: LinkQualityError | None = None
        self._bad_seen = 0  # host decoder errors already counted in _quality
        self._last_report: P.StateReport | None = None
        self._closing = threading.Event()
        self._reader: threading.Thread | None = None
        self._t_open = 0.0
        self._servo_requested = False
        self._errors_at_sync = 0
        # bytes written but (by the baud rate) not yet on the line: the OS buffers of a pty or a
        # USB adapter hide this, and a queue of stale setpoints is latency
        self._backlog = 0.0
        self._t_backlog = time.monotonic()
        self._setpoint_len = len(P.encode(P.JointSetpoint(0, (0.0,) * P.N_JOINTS, (0.0,) * P.N_JOINTS), 0))

    # ------------------------------------------------------------------ life cycle
    def open(self) -> P.VersionInfo:
        """Open the port, start the reader, say HELLO; return the bridge's VERSION answer.

        Raises:
            LinkError: the port cannot be opened, or no VERSION came within ack_timeout_s.
        """
        self._closing.clear()
        self.decoder = P.Decoder()
        self._errors_at_sync = 0
        with self._cond:
            self._error = None
            self._quality = QualityWindow(self.params.quality_window_s)
            self._quality_error = None
            self._bad_seen = 0
            self._last_report = None
            self._history.clear()
            self._joints = JointHistory(self.params.history_s)
            self._replies.clear()
            self._offsets.clear()
        try:
            self._ser = serial.serial_for_url(self.port, baudrate=self.params.baud, timeout=0.02,
                                              write_timeout=0)
        except (serial.SerialException, OSError, ValueError) as e:
            raise LinkError(f"cannot open {self.port}: {e}. Is the bridge (or `photoservo pa10-sim`) "
                            "running and is this its port?") from None
        try:
            self._ser.reset_input_buffer()
        except (serial.SerialException, OSError):
            pass
        self._t_open = time.monotonic()
        self._reader = threading.Thread(target=self._read_loop, name="pa10-link-reader", daemon=True)
        self._reader.start()
        try:
            reply = self._request(P.Hello(client_id=0x5053), expect=P.VersionInfo)
        except LinkError as e:
            self.close()
            q = self.quality()
            if q.bad_frames:  # something answered, garbled: a noisy line, not a wrong port
                raise LinkQualityError(f"{e} Meanwhile {q.bad_frames} bad frames arrived: "
                                       f"{q.advice(0.0, self.simulated)}") from None
            raise
        assert isinstance(reply, P.VersionInfo)
        self.version = reply
        return reply

    def close(self) -> None:
        """Stop the reader and close the port. Does not talk to the bridge (see __exit__)."""
        self._closing.set()
        if self._reader is not None and self._reader is not threading.current_thread():
            self._reader.join(timeout=1.0)
        if self._ser is not None:
            try:
                self._ser.close()
            except (serial.SerialException, OSError):
                pass
        self._ser = None

    def __enter__(self) -> Self:
        if self.version is None or self._ser is None:
            self.open()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            why = self.safe_stop()
            if why and exc_type is None:
                raise LinkError(why)
        finally:
            self.close()

    def safe_stop(self, timeout: float = 5.0) -> str:
        """Controlled stop and servo off if the servo is on and the bridge answers (also after
        the quality gate tripped). Returns "" when done or not needed, else a sentence saying
        the bridge's setpoint watchdog stops the arm (no more setpoints come)."""
        if not self._servo_requested or self._error is not None or self._ser is None:
            return ""
        try:
            try:
                self.stop()
                self.wait_until_still(timeout=timeout)
            finally:
                self.disable()
        except LinkError:
            return "The bridge did not confirm the controlled stop; its setpoint watchdog stops the arm."
        return ""

    # ------------------------------------------------------------------ commands
    def enable(self) -> None:
        """Servo on (brakes released, holding the measured position). Raises LinkError on NACK."""
        self._request(P.Servo(True))
        self._servo_requested = True

    def disable(self) -> None:
        """Servo off: the bridge stops any motion within the limits, then engages the brakes."""
        self._request(P.Servo(False))
        self._servo_requested = False

    def stop(self) -> None:
        """Controlled stop: the bridge drops the setpoint stream and decelerates to rest."""
        self._request(P.Stop())

    def estop(self) -> None:
        """Emergency stop: brakes at once, fault latched until clear_fault()."""
        self._request(P.EStop())
        self._servo_requested = False

    def clear_fault(self) -> None:
        self._request(P.ClearFault())

    def tool(self, on: bool, output: int = 0) -> None:
        """Switch a tool output (0 = the collection net / gripper)."""
        self._request(P.Tool(output, on))

    def send_setpoint(self, q, dq, t_host: float | None = None) -> int | None:
        """Send one joint setpoint (rad, rad/s) stamped `t_host` (default now). Never blocks:
        returns its sequence number, or None when the line was still busy with earlier bytes
        (the setpoint is dropped and counted in `setpoints_dropped`), or when the latest state
        report says the bridge is making a controlled stop (its watchdog's, or one asked for):
        it refuses setpoints until the arm is at rest, so none is sent (`setpoints_held`). The
        caller's motion re-plans from the measured state once the bridge takes them again.

        Raises:
            LinkError: the bridge has gone silent or away.
        """
        self._check(quality=True)
        with self._cond:
            stopping = bool(self._history) and bool(self._history[-1].status & P.Status.STOPPING)
        if stopping:
            self.setpoints_held += 1
            return None
        t = time.monotonic() if t_host is None else t_host
        msg = P.JointSetpoint(int(t * 1e6), tuple(np.asarray(q, float).tolist()),
                              tuple(np.asarray(dq, float).tolist()))
        seq = self._write(msg, droppable=True)
        if seq is None:
            self.setpoints_dropped += 1
        else:
            self.setpoints_sent += 1
        return seq

    # ------------------------------------------------------------------ state
    def state(self) -> JointState:
        """The latest state report.

        Raises:
            LinkError: none received within silence_timeout_s (bridge silent), or the port failed.
            LinkQualityError: the link-quality gate tripped (see the module docstring).
        """
        self._check(quality=True)
        with self._cond:
            if not self._history:
                raise LinkError(f"no state from the bridge on {self.port} yet")
            return self._history[-1]

    def wait_state(self, after: float | None = None, timeout: float | None = None) -> JointState:
        """Block until a state report received after host time `after` (default now) arrives."""
        after = time.monotonic() if after is None else after
        deadline = time.monotonic() + (self.params.silence_timeout_s if timeout is None else timeout)
        with self._cond:
            while True:
                self._check_locked()
                if self._history and self._history[-1].t_rx > after:
                    return self._history[-1]
                left = deadline - time.monotonic()
                if left <= 0:
                    raise self._silent_error()
                self._cond.wait(min(left, 0.05))

    def wait_until_still(self, timeout: float = 5.0) -> JointState:
        """Wait until the bridge reports no joint moving (after a stop)."""
        deadline = time.monotonic() + timeout
        while True:
            s = self.wait_state()
            if not s.moving and not (s.status & P.Status.STOPPING):
                return s
            if time.monotonic() > deadline:
                raise LinkError(f"arm still moving {timeout:.1f} s after a stop; check the bridge")

    def history(self) -> list[JointState]:
        """The kept state reports (the last history_s seconds), oldest first."""
        with self._cond:
            return list(self._history)

    def state_at(self, t: float) -> JointState:
        """Joint state at host monotonic time `t` (s), linearly interpolated between the two
        recent states around it (positions and velocities). For the vision loop: where the
        cameras were at a frame's capture time. A `t` newer than the latest state is
        extrapolated with its velocity by at most 2 state periods.

        Raises:
            LookupError: `t` is older than the kept history or too far in the future.
            LinkError: the bridge is silent or gone.
        """
        self._check()
        with self._cond:
            if not self._history:
                raise LookupError("no state received yet")
            last, joints = self._history[-1], self._joints
        period = (self.version.state_period_us * 1e-6) if self.version else 0.004
        joints.ahead_s = 2 * period + 1e-3
        q, dq = joints.at(t)
        return JointState(t, last.t_rx, q, dq, last.status, last.fault, last.report)

    def flange_at(self, t: float, T_flange_tool: np.ndarray | None = None) -> np.ndarray:
        """Pose of the flange (or of a tool / the left camera attached by T_flange_tool) in the
        base frame at host time `t`: fk(state_at(t).q), 4x4, mm. Raises as `state_at`."""
        return fk(self.state_at(t).q, T_flange_tool)

    @property
    def crc_errors(self) -> int:
        """Frames from the bridge dropped by the host for a bad CRC/COBS/length/version/type,
        not counting the tail of a frame that was on the line when the port was opened."""
        return self.decoder.errors - self._errors_at_sync

    @property
    def resyncs(self) -> int:
        return self.decoder.resyncs

    def quality(self) -> LinkQuality:
        """The link-quality numbers now (totals since open, rates over quality_window_s)."""
        with self._cond:
            return self._quality.snapshot(time.monotonic())

    # ------------------------------------------------------------------ internals
    def _check(self, quality: bool = False) -> None:
        with self._cond:
            self._check_locked()
            if quality:
                self._check_quality_locked()

    def _check_quality_locked(self) -> None:
        """The link-quality gate: raise (and latch) LinkQualityError once a rate passes its limit."""
        if self._quality_error is not None:
            raise self._quality_error
        p = self.params
        q = self._quality.snapshot(time.monotonic())
        over = q.over(p.max_bad_frames_per_s, p.max_refused_per_s, p.max_watchdog_per_s)
        if not over:
            return
        self._quality_error = LinkQualityError(
            f"link to the bridge on {self.port} failed the quality gate: {over} in the last {q.window_s:g} s "
            f"({q.totals()} since the start); controlled stop. {q.advice(p.max_bad_frames_per_s, self.simulated)}")
        raise self._quality_error

    def _check_locked(self) -> None:
        if self._error is not None:
            raise self._error
        if self._ser is None:
            raise LinkError(f"link to {self.port} is closed; call open() (or use `with Link(...)`)")
        last = self._history[-1].t_rx if self._history else self._t_open
        if time.monotonic() - last > self.params.silence_timeout_s and self.version is not None:
            raise self._silent_error()

    def _silent_error(self) -> LinkError:
        last = self._history[-1].t_rx if self._history else self._t_open
        what = f"{time.monotonic() - last:.2f} s (limit {self.params.silence_timeout_s:.2f} s)"
        q = self._quality.snapshot(time.monotonic())
        if self.simulated:
            why = ("The simulator's bridge (emulator) did not get the CPU: the machine is too busy; close "
                   "other programs or raise [link] silence_timeout_s.")
        elif q.bad_frames_per_s:  # garbled rather than silent
            why = f"{q.bad_frames_per_s * q.window_s:.0f} bad frames in the last {q.window_s:g} s. {q.advice(0.0, False)}"
        else:
            why = "Check the cable and the bridge power, then reconnect."
        return LinkError(f"bridge on {self.port} silent (no valid state) for {what}; the arm stops by "
                         f"itself (watchdog). {why}")

    def _next_seq(self) -> int:
        self._seq = (self._seq + 1) & 0xFFFF
        return self._seq

    def _write(self, msg: P.Message, droppable: bool) -> int | None:
        """Write one frame without blocking. Bytes the OS did not take are kept and sent first
        next time; a droppable message that finds such bytes waiting is dropped instead."""
        ser = self._ser
        if ser is None:
            raise LinkError(f"link to {self.port} is closed")
        with self._tx_lock:
            now = time.monotonic()
            self._backlog = max(0.0, self._backlog - (now - self._t_backlog) * self.params.baud / 10.0)
            self._t_backlog = now
            try:
                if self._tx_pending:
                    n = ser.write(self._tx_pending) or 0
                    self._tx_pending = self._tx_pending[n:]
                    if self._tx_pending and droppable:
                        return None
                if droppable and self._backlog > self.MAX_BACKLOG_FRAMES * self._setpoint_len:
                    return None  # the line is still busy with earlier setpoints: this one is late
                seq = self._next_seq()
                data = self._tx_pending + P.encode(msg, seq)
                n = ser.write(data) or 0
                self._tx_pending = data[n:]
                self._backlog += len(data)
                return seq
            except (serial.SerialException, OSError) as e:
                self._fail(f"writing to {self.port} failed ({e})")
                raise self._error from None  # type: ignore[misc]

    def _flush_pending(self) -> None:
        with self._tx_lock:
            if self._tx_pending and self._ser is not None:
                n = self._ser.write(self._tx_pending) or 0
                self._tx_pending = self._tx_pending[n:]

    def _request(self, msg: P.Message, expect: type = P.Ack, tries: int = 3) -> P.Message:
        """Send a control message and wait for its ACK (VERSION for HELLO). Every control message
        is idempotent, so an unanswered one is sent again (new seq), `tries` times in all."""
        what = msg.TYPE.name
        for _ in range(tries):
            self._check()
            seq = self._write(msg, droppable=False)
            deadline = time.monotonic() + self.params.ack_timeout_s / tries
            with self._cond:
                while True:
                    if self._error is not None:
                        raise self._error
                    key = seq if expect is P.Ack else -1
                    reply = self._replies.pop(key, None)
                    if isinstance(reply, P.Nack):
                        raise LinkError(describe_nack(reply, self.joint_names))
                    if isinstance(reply, expect):
                        return reply
                    left = deadline - time.monotonic()
                    if left <= 0:
                        break
                    self._cond.wait(min(left, 0.05))
        raise LinkError(f"no answer to {what} from the bridge on {self.port} within "
                        f"{self.params.ack_timeout_s:.2f} s ({tries} tries). Is the bridge running "
                        "and is the baud rate right?")

    def _fail(self, why: str) -> None:
        with self._cond:
            if self._error is None:
                advice = ("The simulator ended" if self.simulated else
                          "Check the cable and the bridge, then reconnect")
                self._error = LinkError(f"bridge on {self.port} went away: {why}. The arm stops by "
                                        f"itself (watchdog). {advice}.")
            self._cond.notify_all()

    def _on_frame(self, frame: P.Frame, t_rx: float) -> None:
        m = frame.msg
        if self.decoder.frames == 1:
            self._errors_at_sync = self.decoder.errors
        with self._cond:
            if isinstance(m, P.StateReport) and not all(map(math.isfinite, m.q + m.dq)):
                self._quality.add(t_rx, BAD)  # a bridge fault, not a state: counted, never used
            elif isinstance(m, P.StateReport):
                off = self._offsets.add(t_rx - m.t_bridge_us * 1e-6)  # bridge clock -> host clock
                s = JointState(m.t_bridge_us * 1e-6 + off, t_rx, np.array(m.q), np.array(m.dq),
                               P.Status(m.status), P.Fault(m.fault) if m.fault in P.Fault._value2member_map_
                               else P.Fault.INTERNAL, m)
                self._count_report(m, t_rx)
                if self._history and s.t < self._history[-1].t:
                    self._history.clear()  # bridge clock jumped (restart): start over
                    self._joints = JointHistory(self.params.history_s)
                self._history.append(s)
                self._joints.append(s.t, s.q, s.dq)
                while self._history and s.t - self._history[0].t > self.params.history_s:
                    self._history.popleft()
            elif isinstance(m, P.VersionInfo):
                self._replies[-1] = m
            elif isinstance(m, (P.Ack, P.Nack)):
                if isinstance(m, P.Nack):
                    self.nacks.append(m)
                    if m.msg_type == P.MsgType.SETPOINT:
                        self.refused += 1
                        self._quality.add(t_rx, REFUSED)
                self._replies[m.seq] = m
                if len(self._replies) > 256:
                    self._replies.pop(next(iter(self._replies)))
            self._cond.notify_all()

    def _count_report(self, m: P.StateReport, t_rx: float) -> None:
        bad, watchdog = report_events(self._last_report, m)
        self._quality.add(t_rx, BAD, bad)
        self._quality.add(t_rx, WATCHDOG, watchdog)
        self._last_report = m

    def _read_loop(self) -> None:
        ser = self._ser
        assert ser is not None
        while not self._closing.is_set():
            try:
                data = ser.read(max(1, ser.in_waiting))
                if self._tx_pending:
                    self._flush_pending()
            except (serial.SerialException, OSError, TypeError, AttributeError) as e:
                if not self._closing.is_set():
                    self._fail(str(e) or type(e).__name__)
                return
            if not data:
                continue
            t_rx = time.monotonic()
            for frame in self.decoder.iter_feed(data):
                self._on_frame(frame, t_rx)
            if self.decoder.frames:  # bad frames on the host side, once in sync
                bad = self.crc_errors
                if bad > self._bad_seen:
                    with self._cond:
                        self._quality.add(t_rx, BAD, bad - self._bad_seen)
                    self._bad_seen = bad
