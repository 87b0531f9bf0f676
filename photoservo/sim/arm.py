"""The simulator's arm on the simulation's clock: the controller emulator's bridge
(sim/emulator.py `BridgeModel`) behind the wire protocol, an `Arm` (robot/arm.py) like the
serial `robot.link.Link` the real-time runs use."""

from __future__ import annotations

import numpy as np

from photoservo.robot import protocol as P
from photoservo.robot.arm import Arm, ArmState, JointHistory
from photoservo.robot.link import LinkError
from photoservo.robot.pa10 import PA10Limits
from photoservo.sim.bridge import BridgeModel, EmulatorParams


class LockstepArm(Arm):
    """The controller emulator's bridge (sim/emulator.py `BridgeModel`) clocked by the
    simulation instead of a thread: every host message is encoded with the wire protocol and
    decoded by a protocol `Decoder` — the same bytes a pty would carry — but time advances only
    when the session calls `tick(now)`, so a lockstep run is deterministic. The session's
    real-time mode uses the emulator on a pty and `robot.link.Link` instead; both offer the calls
    below."""

    def __init__(self, params: EmulatorParams, limits: PA10Limits, q0: np.ndarray, now: float = 0.0) -> None:
        self.model = BridgeModel(limits, params, q0, now)
        self.decoder = P.Decoder()
        self.now = now
        self._seq = 0
        self._last: ArmState | None = None
        self.history = JointHistory(keep_s=4.0, ahead_s=float("inf"))
        self.nacks: list[P.Nack] = []
        self.state_period = 1.0 / params.state_hz
        self._t_report = -1.0
        self._record()

    def _send(self, msg) -> list:
        self._seq = (self._seq + 1) & 0xFFFF
        replies = []
        for frame in self.decoder.feed(P.encode(msg, self._seq)):
            replies += self.model.handle(frame, self.now)
        for r in replies:
            if isinstance(r, P.Nack):
                self.nacks.append(r)
        return replies

    def _request(self, msg) -> None:
        for r in self._send(msg):
            if isinstance(r, P.Nack):
                raise LinkError(f"bridge refused {type(msg).__name__}: error {P.Error(r.error).name}")

    def enable(self) -> None:
        self._request(P.Servo(True))

    def disable(self) -> None:
        self._request(P.Servo(False))

    def stop(self) -> None:
        self._request(P.Stop())

    def tool(self, on: bool, output: int = 0) -> None:
        self._request(P.Tool(output, on))

    def send_setpoint(self, q: np.ndarray, dq: np.ndarray, t_host: float | None = None) -> int:
        t = self.now if t_host is None else t_host
        self._send(P.JointSetpoint(int(t * 1e6), tuple(np.asarray(q, float).tolist()),
                                   tuple(np.asarray(dq, float).tolist())))
        return self._seq

    def tick(self, now: float) -> None:
        """Advance the bridge by one control period ending at `now` (s)."""
        self.now = now
        self.model.tick(now)
        self._record()

    def _record(self) -> None:
        m = self.model
        self._last = ArmState(self.now, m.q.copy(), m.dq.copy(), m.status(), P.Fault(m.fault))
        self.history.append(self.now, self._last.q, self._last.dq)

    def state(self) -> ArmState:
        """The latest state (as a state report at the bridge's state rate would give it)."""
        return self._last

    def state_at(self, t: float) -> ArmState:
        """Joint state at simulated time t, interpolated between ticks (the latest at or after
        the last tick: the bridge holds it until the next tick)."""
        last = self._last
        if t >= last.t:
            return last
        q, dq = self.history.at(t)
        return ArmState(t, q, dq, last.status, last.fault)

    def close(self) -> None:
        pass
