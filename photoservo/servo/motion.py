"""Jerk-limited joint motion for the PA-10 with Ruckig (method step 6: "joint motion is made
jerk-limited with Ruckig and streamed to the arm's controller").

One step per control period (default 250 Hz), starting from the measured joint state:

    inp.current_position, inp.current_velocity = q_meas, dq_meas
    otg.update(inp, out)  ->  Setpoint(out.new_position, out.new_velocity, out.new_acceleration)

The measured state is late (line, bridge period), so re-planning every step from it limit-cycles
around the target (tests/test_motion.py::test_lagging_arm_reaches_the_target_and_settles). So a
step continues from the last setpoint (Ruckig's pass_to_input) while the measured joints are
within `track_tolerance_deg` of one of the setpoints of the last `track_window_s`, and otherwise
starts from the measured state, saying so in `reason` (first step, after a fault, an arm that
lags or was pushed; `track_tolerance_deg = 0` always re-plans). A re-plan starts from the last
commanded acceleration. Pure code: arrays in, setpoints out, no I/O and no clock.

Ruckig's free edition ignores position limits, so the safety layer is ours, on top of each step:

1. Speed override (0-100 %) scales the joint speed limits; 0 % makes a controlled stop.
2. Joint ranges: targets keep `joint_margin_deg` clear of the range ends; while moving, a
   joint's speed toward an end is capped at the speed from which it can still stop (jerk-
   limited) within half the margin. Velocity targets are likewise scaled down when a keep-out
   volume approaches the water plane or a box face (servo/keepout.py approach_caps).
3. Tool-speed cap under `tool_speed_max_mm_s` (velocity targets scaled down; a move is
   time-scaled, v·s, a·s², j·s³, which keeps its path).
4. Braking check: a step is accepted only if a controlled stop from it stays inside the joint
   ranges (less half the margin) and keeps the arm's VOLUMES (link capsules, the camera rig +
   tool box) above the water plane (`z_min_mm`) and inside the workspace box, checked
   continuously along the stop (servo/keepout.py), as a move's whole path is when adopted.
   Otherwise the arm is told to stop: while it follows the plan that stop was checked; after a
   re-plan from an off-plan state, stopping is still the best there is.

Every step returns what the arm will actually be told, `reason` naming the clamp that acted
("" when none did), as LeRobot's `send_action` does.

Frames and units: joint angles in rad, base frame in mm (z up), time in s.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from ruckig import (
    ControlInterface,
    InputParameter,
    OutputParameter,
    Result,
    Ruckig,
    RuckigError,
    Synchronization,
    Trajectory,
)

from photoservo.errors import InputError
from photoservo.servo.braking import stopping_speed
from photoservo.servo.keepout import Keepout
from photoservo.robot.pa10 import (
    JOINT_NAMES,
    N_JOINTS,
    PA10Limits,
    jacobian,
    tool_offset,
)

@dataclass(frozen=True)
class MotionParams:
    """[motion] config: control rate, speed override, joint margin, Cartesian keep-out."""

    rate_hz: float  # control (setpoint) rate (Hz)
    speed_override_pct: float  # 0..100: scales joint speed limits
    joint_margin_deg: float  # kept clear at each end of every joint range (deg)
    position_tolerance_deg: float  # a move is done when every joint is this close (deg)
    z_min_mm: float  # the water: no checked point may go below this height (base frame, mm)
    workspace_min_mm: tuple[float, float, float]  # workspace box, lower corner (base frame, mm)
    workspace_max_mm: tuple[float, float, float]  # workspace box, upper corner (base frame, mm)
    tool_speed_max_mm_s: float  # cap on the tool point's speed (mm/s)
    tool_offset_mm: tuple[float, float, float]  # tool point in the flange frame (mm)
    link_radii_mm: tuple[float, float, float]  # keep-out capsule radii: upper arm, forearm, wrist (mm)
    rig_box_min_mm: tuple[float, float, float]  # keep-out box of the camera rig + tool, flange frame (mm)
    rig_box_max_mm: tuple[float, float, float]
    track_tolerance_deg: float  # measured joints this close to a recent setpoint = following the plan
    track_window_s: float  # how far back "recent" reaches: the state's expected lateness (s)

    def validate(self, where: str) -> None:
        def bad(key: str, why: str) -> InputError:
            return InputError(f"config key '{where}.{key}' {why}, got {getattr(self, key)}")

        if not self.rate_hz > 0:
            raise bad("rate_hz", "must be > 0")
        if not 0.0 <= self.speed_override_pct <= 100.0:
            raise bad("speed_override_pct", "must be in 0..100")
        if not self.joint_margin_deg >= 0:
            raise bad("joint_margin_deg", "must be >= 0")
        if not self.position_tolerance_deg > 0:
            raise bad("position_tolerance_deg", "must be > 0")
        if not self.tool_speed_max_mm_s > 0:
            raise bad("tool_speed_max_mm_s", "must be > 0")
        if not self.track_tolerance_deg >= 0:
            raise bad("track_tolerance_deg", "must be >= 0")
        if not self.track_window_s > 0:
            raise bad("track_window_s", "must be > 0")
        for i in range(3):
            if not self.workspace_min_mm[i] < self.workspace_max_mm[i]:
                raise bad("workspace_max_mm", f"must exceed workspace_min_mm on axis {'xyz'[i]}")
        if not self.workspace_min_mm[2] <= self.z_min_mm < self.workspace_max_mm[2]:
            raise bad("z_min_mm", "must lie inside the workspace box's z range")
        if not all(0.0 <= r <= 500.0 for r in self.link_radii_mm):
            raise bad("link_radii_mm", "must be 3 radii in 0..500 mm")
        for i in range(3):
            if not -2000.0 <= self.rig_box_min_mm[i] < self.rig_box_max_mm[i] <= 2000.0:
                raise bad("rig_box_max_mm", f"must exceed rig_box_min_mm on axis {'xyz'[i]}, both within +-2000 mm")


@dataclass(frozen=True, eq=False)
class Setpoint:
    """What the arm is told for the next period: joint position q (rad), velocity dq (rad/s),
    acceleration ddq (rad/s^2). `reason` names the safety clamp that changed it ("" = none)."""

    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    reason: str = ""


class Motion:
    """Online jerk-limited motion at the control rate: position moves, velocity following and a
    controlled stop, each step from the measured joint state, with the safety layer above.

    `params` is the [motion] config, `limits` the arm's (configs/pa10.toml, `load_limits()`);
    `T_flange_tool` (4x4, mm), when given, replaces [motion] tool_offset_mm as the tool point
    that the keep-out and the tool-speed cap apply to. Use one Motion per arm and call one of
    the three steps once per control period with the latest state.

    >>> from photoservo.robot.pa10 import HOME_Q, load_limits
    >>> from photoservo.config import load_config
    >>> m = Motion(load_config().motion, load_limits())
    >>> q, dq = HOME_Q.copy(), np.zeros(7)
    >>> target = HOME_Q + 0.1
    >>> while not m.done:
    ...     sp = m.move_step(q, dq, target)
    ...     q, dq = sp.q, sp.dq          # a perfect arm; the real loop reads the link's state
    >>> bool(np.allclose(q, target))
    True
    """

    _BRAKE_SAMPLE_S = 0.02  # sampling step of the braking trajectory in the braking check (s)
    _CAP_MARGIN_MM = 25.0  # the keep-out caps aim this far inside the boundaries (the braking check is the guarantee)

    def __init__(self, params: MotionParams, limits: PA10Limits, T_flange_tool: np.ndarray | None = None):
        self.params = params
        self.limits = limits
        self.dt = 1.0 / params.rate_hz
        self.T_flange_tool = tool_offset(0.0) if T_flange_tool is None else np.asarray(T_flange_tool, float)
        if T_flange_tool is None:
            self.T_flange_tool[:3, 3] = params.tool_offset_mm
        m = math.radians(params.joint_margin_deg)
        self.q_lo_target, self.q_hi_target = limits.q_min + m, limits.q_max - m
        self.q_lo_safe, self.q_hi_safe = limits.q_min + m / 2, limits.q_max - m / 2
        self.otg = Ruckig(N_JOINTS, self.dt)
        self.inp = InputParameter(N_JOINTS)
        self.out = OutputParameter(N_JOINTS)
        self._brake_otg = Ruckig(N_JOINTS)
        self._brake_inp = InputParameter(N_JOINTS)
        self._brake_inp.control_interface = ControlInterface.Velocity
        self._brake_inp.max_velocity = limits.dq_max
        self._brake_inp.max_acceleration = limits.ddq_max
        self._brake_inp.max_jerk = limits.dddq_max
        self._brake_inp.target_velocity = np.zeros(N_JOINTS)
        self._brake_inp.target_acceleration = np.zeros(N_JOINTS)
        self._brake_inp.synchronization = Synchronization.No  # as stop_step brakes
        self._traj = Trajectory(N_JOINTS)
        # keep-out approach caps: the weakest joint's deceleration / jerk at a 500 mm lever
        self._a_cart = float(limits.ddq_max.min()) * 500.0
        self._j_cart = float(limits.dddq_max.min()) * 500.0
        self.keepout = Keepout(params.z_min_mm, params.workspace_min_mm, params.workspace_max_mm,
                               params.link_radii_mm, params.rig_box_min_mm, params.rig_box_max_mm,
                               self.T_flange_tool)
        self._override = params.speed_override_pct / 100.0
        self._last: Setpoint | None = None
        self._history: deque[np.ndarray] = deque(maxlen=max(1, round(params.track_window_s * params.rate_hz)))
        #: how old the measured state given to the next step is (s), set by the caller (0: now)
        self.state_age_s = 0.0
        self._target: np.ndarray | None = None
        self._refused: str = ""
        self._time_scale = 1.0
        self.done = False

    @property
    def speed_override_pct(self) -> float:
        return 100.0 * self._override

    @speed_override_pct.setter
    def speed_override_pct(self, pct: float) -> None:
        if not 0.0 <= pct <= 100.0:
            raise InputError(f"speed override {pct} % is outside 0..100 %")
        self._override = pct / 100.0
        self._target = None  # re-plan (and re-scale) the current move at the new speed

    def keepout_violation(self, q: np.ndarray) -> str:
        """'' when the arm's volumes at q (rad; (7,) or a path (N, 7)) are above the water plane
        and inside the workspace box, else a message naming the volume and the limit."""
        return self.keepout.violation(q)

    def check_target(self, q_target: np.ndarray, q_start: np.ndarray | None = None) -> None:
        """Raise InputError naming the joint or the limit when q_target (rad) is outside the
        joint ranges less the margin or its pose breaks the keep-out; with q_start, also when
        the Ruckig path from rest at q_start to q_target crosses the keep-out."""
        q = np.asarray(q_target, dtype=float)
        self.limits.check(q, "target")
        for j, n in enumerate(JOINT_NAMES):
            if not self.q_lo_target[j] <= q[j] <= self.q_hi_target[j]:
                raise InputError(
                    f"target: joint {n} = {math.degrees(q[j]):.2f} deg is within joint_margin_deg = "
                    f"{self.params.joint_margin_deg:g} of its range [{math.degrees(self.limits.q_min[j]):.1f}, "
                    f"{math.degrees(self.limits.q_max[j]):.1f}] deg")
        why = self.keepout_violation(q)
        if why:
            raise InputError(f"target: {why}")
        if q_start is not None:
            why = self._path_violation(np.asarray(q_start, float), np.zeros(N_JOINTS), np.zeros(N_JOINTS), q)
            if why:
                raise InputError(f"target: the path to it: {why}")

    def move_step(self, q_meas: np.ndarray, dq_meas: np.ndarray, q_target: np.ndarray) -> Setpoint:
        """One period of a jerk-limited move to q_target (rad), from the measured q (rad) and
        dq (rad/s). A target outside the ranges/keep-out is refused: the arm stops and `reason`
        says why. `done` becomes True once every joint is within position_tolerance_deg, at rest."""
        q_target = np.asarray(q_target, dtype=float)
        q_arm = np.asarray(q_meas, float)
        q_meas, dq_meas, note = self._seed(q_meas, dq_meas)
        if self._target is None or not np.array_equal(q_target, self._target):
            self._adopt(q_meas, dq_meas, q_target)
        if self._refused:
            sp = self.stop_step(q_meas, dq_meas, reason=self._refused)
            self.done = False
            return sp
        if self._override <= 0.0:
            return self.stop_step(q_meas, dq_meas, reason="speed override 0 %")
        inp = self._current(q_meas, dq_meas)
        inp.control_interface = ControlInterface.Position
        inp.target_position = q_target
        inp.target_velocity = np.zeros(N_JOINTS)
        inp.target_acceleration = np.zeros(N_JOINTS)
        reasons = [note] if note else []
        v_cap_lo, v_cap_hi = self._range_caps(q_meas)
        _, J = self.keepout.point_jacobians(q_meas)
        sp = None
        for _ in range(3):
            s = self._time_scale
            v = self._override * self.limits.dq_max * s
            inp.max_velocity = np.maximum(np.minimum(v, v_cap_hi), 1e-6)
            inp.min_velocity = -np.maximum(np.minimum(v, v_cap_lo), 1e-6)
            inp.max_acceleration = self.limits.ddq_max * s * s
            inp.max_jerk = self.limits.dddq_max * s**3
            result = self._update(inp)
            if result not in (Result.Working, Result.Finished):
                return self.stop_step(q_meas, dq_meas, reason=f"Ruckig refused the move ({result})")
            sp = self._from_out()
            speed = float(np.linalg.norm(J[-1] @ sp.dq))  # tool point (Jacobian one period old)
            if speed <= 1.02 * self.params.tool_speed_max_mm_s:
                break
            self._time_scale *= self.params.tool_speed_max_mm_s / speed
            reasons.append("tool speed cap")
        v = self._override * self.limits.dq_max * self._time_scale
        slowed = (((v_cap_hi < v) & (sp.dq >= 0.98 * v_cap_hi) & (sp.dq > 0))
                  | ((v_cap_lo < v) & (-sp.dq >= 0.98 * v_cap_lo) & (sp.dq < 0)))
        if slowed.any():
            reasons.append("joint range: slowing " + ", ".join(np.array(JOINT_NAMES)[slowed]))
        checked = self._accept(q_meas, dq_meas, sp, reasons)
        err = np.abs(q_arm - q_target)
        self.done = bool(result == Result.Finished and np.all(err <= math.radians(self.params.position_tolerance_deg))
                         and not checked.reason.startswith("braking"))
        return checked

    def velocity_step(self, q_meas: np.ndarray, dq_meas: np.ndarray, dq_target: np.ndarray) -> Setpoint:
        """One period following the joint-velocity target dq_target (rad/s), e.g. from the servo
        law's DLS solve, from the measured q (rad) and dq (rad/s). The target is clamped to the
        overridden speed limits, the joint-range caps and the tool-speed cap before Ruckig
        reaches it jerk-limited."""
        q_meas, dq_meas, note = self._seed(q_meas, dq_meas)
        self._target = None
        self.done = False
        if self._override <= 0.0:
            return self.stop_step(q_meas, dq_meas, reason="speed override 0 %")
        dq_t = np.asarray(dq_target, dtype=float).copy()
        if dq_t.shape != (N_JOINTS,) or not np.all(np.isfinite(dq_t)):
            return self.stop_step(q_meas, dq_meas, reason="velocity target is not 7 finite numbers")
        reasons = [note] if note else []
        v = self._override * self.limits.dq_max
        m = float(np.max(np.abs(dq_t) / v))
        if m > 1.0:
            dq_t /= m  # keep the direction
            reasons.append("joint speed limit")
        P, J = self.keepout.point_jacobians(q_meas)
        dq_t, near = self.keepout.approach_caps(P, J, dq_t, 2 * self.dt, self._a_cart, self._j_cart, self._CAP_MARGIN_MM)
        if near:
            reasons.append("keep-out: slowing the " + ", ".join(near))
        v_cap_lo, v_cap_hi = self._range_caps(q_meas)
        clipped = np.clip(dq_t, -v_cap_lo, v_cap_hi)
        if np.any(clipped != dq_t):
            names = np.array(JOINT_NAMES)[clipped != dq_t]
            reasons.append("joint range: slowing " + ", ".join(names))
            dq_t = clipped
        speed = float(np.linalg.norm(J[-1] @ dq_t))  # the tool point
        if speed > self.params.tool_speed_max_mm_s:
            dq_t *= self.params.tool_speed_max_mm_s / speed
            reasons.append("tool speed cap")
        inp = self._current(q_meas, dq_meas)
        inp.control_interface = ControlInterface.Velocity
        inp.target_velocity = dq_t
        inp.target_acceleration = np.zeros(N_JOINTS)
        inp.max_velocity = self.limits.dq_max
        inp.max_acceleration = self.limits.ddq_max
        inp.max_jerk = self.limits.dddq_max
        result = self._update(inp)
        if result not in (Result.Working, Result.Finished):
            sp = self.stop_step(q_meas, dq_meas, reason=f"Ruckig refused the velocity target ({result})")
        else:
            sp = self._accept(q_meas, dq_meas, self._from_out(), reasons, P)
        self.done = False
        return sp

    def stop_step(self, q_meas: np.ndarray, dq_meas: np.ndarray, reason: str = "") -> Setpoint:
        """One period of a controlled stop: velocity brought to zero with the full acceleration
        and jerk limits, each joint as fast as it can (unsynchronised), from the step's start
        state (see the module docstring). `done` is True once at rest."""
        q_meas, dq_meas, note = self._seed(q_meas, dq_meas)
        reason = reason or note
        inp = self._current(q_meas, dq_meas)
        inp.control_interface = ControlInterface.Velocity
        inp.target_velocity = np.zeros(N_JOINTS)
        inp.target_acceleration = np.zeros(N_JOINTS)
        inp.max_velocity = self.limits.dq_max
        inp.max_acceleration = self.limits.ddq_max
        inp.max_jerk = self.limits.dddq_max
        inp.synchronization = Synchronization.No  # each joint stops as fast as it can
        result = self._update(inp)
        if result not in (Result.Working, Result.Finished):
            raise RuntimeError(f"Ruckig cannot plan a controlled stop ({result}); emergency-stop the arm")
        sp = self._from_out(reason)
        self._emit(sp)
        self.done = result == Result.Finished
        return sp

    def _seed(self, q_meas, dq_meas) -> tuple[np.ndarray, np.ndarray, str]:
        """The state a step starts from: the last setpoint while the measured joints are within
        track_tolerance_deg of one of the setpoints of the last track_window_s (the arm follows,
        its report is just late), else the measured state, with a note saying why. A measured
        state older than track_window_s (`state_age_s`: the reports stopped coming a while, e.g.
        the simulator's bridge stalled in its pty) tells nothing of whether the arm follows: the
        plan goes on. (Re-planned from such a state, the setpoints jumped back by the distance
        travelled since: the bridge refused them, and its watchdog stopped the arm; a bridge
        that stays silent is the link's `silence_timeout_s` error.)"""
        q_meas, dq_meas = np.asarray(q_meas, float), np.asarray(dq_meas, float)
        tol = math.radians(self.params.track_tolerance_deg)
        if self._last is None or tol == 0:
            return q_meas, dq_meas, ""
        if self.state_age_s > self.params.track_window_s:
            return self._last.q, self._last.dq, ""
        off = np.max(np.abs(np.array(self._history) - q_meas), axis=1)
        if off.min() <= tol:
            return self._last.q, self._last.dq, ""
        d = np.abs(self._last.q - q_meas)
        j = int(np.argmax(d))
        return q_meas, dq_meas, (f"re-planned from the measured state ({JOINT_NAMES[j]} "
                                 f"{math.degrees(d[j]):.2f} deg from the last setpoint)")

    def _emit(self, sp: Setpoint) -> None:
        self._last = sp
        self._history.append(sp.q)

    def _current(self, q_meas: np.ndarray, dq_meas: np.ndarray) -> InputParameter:
        """Ruckig's input seeded from the step's start state (see `_seed`); acceleration = the
        last one commanded. Limits are symmetric unless the caller sets min_velocity again
        (move_step does)."""
        inp = self.inp
        inp.min_velocity = None
        inp.synchronization = Synchronization.Time
        inp.current_position = q_meas
        inp.current_velocity = dq_meas
        inp.current_acceleration = self._last.ddq if self._last is not None else np.zeros(N_JOINTS)
        return inp

    def _update(self, inp: InputParameter) -> Result:
        """otg.update, falling back to unsynchronised joints when Ruckig's time synchronisation
        fails numerically (the Python binding raises RuckigError, e.g. "error in step 2 ... for
        t sync" for some braking states)."""
        try:
            return self.otg.update(inp, self.out)
        except RuckigError:
            if inp.synchronization == Synchronization.No:
                return Result.Error
            inp.synchronization = Synchronization.No
            try:
                return self.otg.update(inp, self.out)
            except RuckigError:
                return Result.Error

    def _from_out(self, reason: str = "") -> Setpoint:
        o = self.out
        return Setpoint(np.array(o.new_position), np.array(o.new_velocity), np.array(o.new_acceleration), reason)

    def _adopt(self, q_meas: np.ndarray, dq_meas: np.ndarray, q_target: np.ndarray) -> None:
        """A new move target: check it and the path, and choose the time scale that keeps the
        tool under its speed cap along the planned path."""
        self._target = q_target.copy()
        self._refused = ""
        self._time_scale = 1.0
        try:
            self.check_target(q_target)
        except InputError as e:
            self._refused = f"refused {e}"
            return
        if self._override <= 0:
            return
        acc = self._last.ddq if self._last is not None else np.zeros(N_JOINTS)
        why = self._path_violation(q_meas, dq_meas, acc, q_target)
        if why:
            self._refused = f"refused target: the path to it: {why}"
            return
        peak = max(self._tool_speed(q, dq) for q, dq in zip(*self._samples()))
        if peak > self.params.tool_speed_max_mm_s:
            self._time_scale = 0.98 * self.params.tool_speed_max_mm_s / peak

    def _plan(self, q0: np.ndarray, dq0: np.ndarray, a0: np.ndarray, q_target: np.ndarray) -> bool:
        """Whole trajectory to q_target into self._traj (override applied, no time scale)."""
        inp = InputParameter(N_JOINTS)
        inp.current_position, inp.current_velocity, inp.current_acceleration = q0, dq0, a0
        inp.target_position = q_target
        inp.max_velocity = np.maximum(self._override * self.limits.dq_max, 1e-6)
        inp.max_acceleration = self.limits.ddq_max
        inp.max_jerk = self.limits.dddq_max
        try:
            return Ruckig(N_JOINTS).calculate(inp, self._traj) in (Result.Working, Result.Finished)
        except RuckigError:
            return False

    def _samples(self, step_s: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
        """(Q, dQ), each (N, 7): self._traj every step_s, ending at its end."""
        n = max(1, math.ceil(self._traj.duration / step_s))
        pv = [self._traj.at_time(min(k * step_s, self._traj.duration))[:2] for k in range(n + 1)]
        return np.array([x[0] for x in pv]), np.array([x[1] for x in pv])

    def _path_violation(self, q0, dq0, a0, q_target) -> str:
        """The planned path to q_target, checked continuously (servo/keepout.py). The time
        scale does not change the path, so the plan without it is checked."""
        if not self._plan(q0, dq0, a0, q_target):
            return "Ruckig cannot plan it"
        v = np.maximum(self._override * self.limits.dq_max, np.abs(dq0))
        return self.keepout.sweep_violation(lambda t: self._traj.at_time(t)[0], self._traj.duration, v)

    def _range_caps(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per joint, the highest speed (>= 0) toward the lower / upper range end from which a
        jerk-limited stop ends inside the range less half the margin. The stop is planned at
        70 % of the acceleration and jerk limits after one period at the joint's top speed, so
        that Ruckig's lag in following the falling cap leaves the braking check (full limits)
        nothing to catch; the joint comes to rest up to one period of top-speed travel before
        the bound."""
        a, j = 0.7 * self.limits.ddq_max, 0.7 * self.limits.dddq_max
        ahead = self.dt * self._override * self.limits.dq_max
        lo = stopping_speed(q - self.q_lo_safe - ahead, a, j)
        hi = stopping_speed(self.q_hi_safe - q - ahead, a, j)
        return lo, hi

    def _tool_speed(self, q: np.ndarray, dq: np.ndarray) -> float:
        return float(np.linalg.norm(jacobian(q, self.T_flange_tool)[:3] @ dq))

    def _accept(self, q_meas: np.ndarray, dq_meas: np.ndarray, sp: Setpoint, reasons: list[str],
                P_meas: np.ndarray | None = None) -> Setpoint:
        """Braking check (safety layer 4): keep `sp` only if a controlled stop from it stays in
        the ranges (less half the margin) and the keep-out; else stop from the measured state.
        P_meas: the keep-out's feature points at q_meas (K, 3) mm, when the caller has them."""
        inp = self._brake_inp
        inp.current_position, inp.current_velocity, inp.current_acceleration = sp.q, sp.dq, sp.ddq
        try:
            result = self._brake_otg.calculate(inp, self._traj)
        except RuckigError:
            result = Result.Error
        if result not in (Result.Working, Result.Finished):
            return self.stop_step(q_meas, dq_meas, reason="braking check: Ruckig cannot plan a stop")
        # Extrema from samples: Trajectory.position_extrema is wrong for the velocity interface
        # in the free edition (pantor/ruckig#215; its min comes out 0). Between samples h apart a
        # joint can pass an extremum by at most ddq_max·h²/8, which is added as slack.
        Q = self._samples(self._BRAKE_SAMPLE_S)[0]
        slack = self.limits.ddq_max * self._BRAKE_SAMPLE_S**2 / 8.0
        lo, hi = Q.min(axis=0) - slack, Q.max(axis=0) + slack
        bad = (lo < self.q_lo_safe) | (hi > self.q_hi_safe)
        if bad.any():
            names = ", ".join(np.array(JOINT_NAMES)[bad])
            return self.stop_step(q_meas, dq_meas, reason=f"braking check: joint range ({names})")
        travel = np.maximum(np.abs(hi - q_meas), np.abs(lo - q_meas))  # from the step's start
        why = self._keepout_on_brake(q_meas, sp, travel, P_meas)
        if why:
            return self.stop_step(q_meas, dq_meas, reason=f"braking check: {why}")
        out = Setpoint(sp.q, sp.dq, sp.ddq, "; ".join(dict.fromkeys(reasons)))
        self._emit(out)
        return out

    def _keepout_on_brake(self, q_start: np.ndarray, sp: Setpoint, dq_travel: np.ndarray,
                          P_start: np.ndarray | None = None) -> str:
        """Keep-out along the braking trajectory in self._traj, from sp: checked when the volumes
        at q_start (feature points P_start (K, 3) mm if known) are nearer a boundary than the step
        and stop could move them (|dq_j| x the reach beyond joint j), then continuously with joint
        speeds <= |dq| + ddq²/(2·jerk)."""
        P = self.keepout.features(q_start) if P_start is None else P_start[None]
        c0 = float(self.keepout.clearance_of(P)[0][0])
        if c0 > float(dq_travel @ self.keepout.reach_mm) + 1e-6:
            return ""
        v = np.abs(sp.dq) + sp.ddq**2 / (2.0 * self.limits.dddq_max) + 1e-9
        return self.keepout.sweep_violation(lambda t: self._traj.at_time(t)[0], self._traj.duration, v)
