"""The PA-10 serial bridge's behaviour, pure and clocked by the caller (no I/O): what the
firmware would do with each message and each control period. The emulator (sim/emulator.py)
puts it on a pty; the lockstep simulator (sim/world.py) drives it directly.

Joints in radians; times in seconds on the bridge clock (sent in µs).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from photoservo.errors import InputError
from photoservo.robot import protocol as P
from photoservo.robot.pa10 import HOME_Q, PA10Limits

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
    it on the bridge's clock or by the host's stamps, whichever is more, between 1 and
    watchdog_periods (so one lost or late frame does not cascade into refusals).
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
        self.t_host_echo_us = 0  # the host's stamp of the last accepted setpoint (us)
        self.last_seq = 0
        self.setpoint_seq: int | None = None
        self.accepted = 0
        self.refused = 0
        self.refusals: dict[str, int] = {}  # refused setpoints by NACK error name
        self.watchdog_stops = 0  # controlled stops for want of setpoints
        self.commands: dict[str, int] = {}  # SERVO_ON, SERVO_OFF, STOP, ESTOP received
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
        if isinstance(m, (P.Servo, P.Stop, P.EStop)):
            name = ("SERVO_ON" if m.enable else "SERVO_OFF") if isinstance(m, P.Servo) else type(m).__name__.upper()
            self.commands[name] = self.commands.get(name, 0) + 1
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
        # periods since q_ref, by this bridge's clock or by the host's stamps, whichever is more:
        # a setpoint the host dropped (line busy) or a bridge that read two at once (its thread
        # late) must not turn the next good one into a refusal; never more than the watchdog's
        k_host = (m.t_host_us - self.t_host_echo_us) * 1e-6 / self.T
        k = 1.0 if self.q_ref is None else min(max(1.0, (now - self.t_last_setpoint) / self.T, k_host),
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

    def describe_end(self) -> str:
        """One line: the commands received (SERVO_ON, STOP, SERVO_OFF, ESTOP), watchdog stops and
        the arm's state now: what a session's end looked like from the bridge."""
        cmds = ", ".join(f"{k} x{n}" for k, n in self.commands.items()) or "no commands"
        state = "moving" if np.any(np.abs(self.dq) > 1e-6) else "still"
        return (f"received {cmds}; watchdog stops {self.watchdog_stops}; arm {state}, "
                f"servo {'on' if self.servo_on else 'off'}{', braked' if self.braked else ''}")

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
