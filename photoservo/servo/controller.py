"""The collection state machine around the servo law (issue 5, Control and Collection): one
control period of position-based visual servoing on the PA-10, `Controller.step`.

Collection (`--collect`):
  servo --(hold error within tolerance for hold_time_s)--> descend --(at collect height)-->
  grasp (tool on, dwell) --> ascend --(back at hover)--> done; any loss of the target while
  descending aborts: climb back to hover height (tool off) and servo again.

Search (issue 10, [servo] search_pose_deg set): servo --(the tracker says out_of_view: the
creature left the view)--> search: a jerk-limited move (Motion.move_step: Ruckig, limits,
keep-out) to the configured joints, then waiting there while the tracker searches the whole
volume --(a pose fresh enough to servo on)--> servo. The search pose is configured, never taken
from an estimate; without it, a creature out of view is waited for where the arm stopped.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np

from photoservo.errors import InputError
from photoservo.geometry import pose_error
from photoservo.robot import pa10
from photoservo.servo.control import (
    ServoParams,
    camera_twist,
    desired_camera_pose,
    estimate_age_limit,
    flange_twist,
    yaw_error_deg,
)
from photoservo.servo.motion import Motion, Setpoint
from photoservo.vision.rig import Rig
from photoservo.vision.track import Track

Phase = Literal["servo", "descend", "grasp", "ascend", "done", "stopped", "search"]
PHASES: tuple[str, ...] = get_args(Phase)
REACH_MM = 1250.0  # distance from the shoulder (S2 axis) beyond which the PA-10 cannot hover


@dataclass
class ControlInfo:
    """What one control period decided (for the status line, the recording and the scores)."""

    t: float
    phase: Phase
    setpoint: Setpoint
    T_base_cam: np.ndarray
    T_base_cam_des: np.ndarray | None
    position_error_mm: float
    yaw_error_deg: float
    stop_reason: str
    tool: bool


PACE_GAIN = 0.25  # smoothing of the measured frame interval and latency (`FramePace`)


@dataclass
class FramePace:
    """The pace of the tracks reaching the controller, measured on its clock: the interval
    between successive frames' capture times and the delivery latency (capture -> the first
    control period that has the track), both smoothed (PACE_GAIN), in s."""

    t_frame: float | None = None  # capture time of the newest track seen (s)
    interval_s: float = 0.0
    latency_s: float = 0.0
    frames: int = 0

    def see(self, now: float, track: Track | None) -> None:
        """A control period at `now` (s) with `track`: measure it if it is a new frame."""
        if track is None or track.t == self.t_frame:
            return
        latency = max(now - track.t, 0.0)
        if self.frames == 0:
            self.latency_s = latency
        else:
            d = track.t - self.t_frame
            self.interval_s = d if self.frames == 1 else self.interval_s + PACE_GAIN * (d - self.interval_s)
            self.latency_s += PACE_GAIN * (latency - self.latency_s)
        self.frames += 1
        self.t_frame = track.t

    def limit_s(self, params: ServoParams) -> float:
        """The age limit at this pace (`estimate_age_limit`); max_estimate_age_s until two frames
        have been seen (one track's age is no latency: it may be a stale one)."""
        if self.frames < 2:
            return params.max_estimate_age_s
        return estimate_age_limit(params, self.latency_s, self.interval_s)


@dataclass
class Controller:
    """One control period of position-based visual servoing (servo/control.py) on the PA-10:
    camera twist -> flange twist -> joint velocities by damped least squares (robot/pa10.py,
    null space pulled toward HOME_Q) -> Ruckig velocity interface with the safety layer
    (servo/motion.py). A controlled stop when the track is missing or older than the age limit
    (`estimate_age_limit`: max_estimate_age_s, longer when frames come slower, at the
    `FramePace` measured here), or the target leaves the reachable workspace."""

    params: ServoParams
    motion: Motion
    T_flange_left: np.ndarray
    T_left_centre: np.ndarray
    collect: bool = False
    search_q: np.ndarray | None = None  # [servo] search_pose_deg (rad), None: hold where stopped
    phase: Phase = "servo"
    height_mm: float = field(default=0.0)
    t_hold_start: float | None = None
    t_grasp: float | None = None
    tool_on: bool = False
    collected: bool = False
    events: list[tuple[float, str]] = field(default_factory=list)
    pace: FramePace = field(default_factory=FramePace)

    def __post_init__(self) -> None:
        self.height_mm = self.params.hover_mm

    def _enter(self, t: float, phase: Phase, why: str) -> None:
        """Change to `phase` at t (s), with its event (`phase_event`)."""
        self.phase = phase
        self.events.append((t, phase_event(phase, why)))

    def step(self, now: float, q: np.ndarray, dq: np.ndarray, track: Track | None,
             t_state: float | None = None) -> ControlInfo:
        """One control period at `now` (s) on the measured joints q (rad), dq (rad/s), measured
        at t_state (s; None: now), toward the tracker's latest `track`."""
        p = self.params
        self.motion.state_age_s = 0.0 if t_state is None else max(0.0, now - t_state)
        dt = self.motion.dt
        T_base_flange = pa10.fk(q)
        T_base_cam = T_base_flange @ self.T_flange_left
        stop = ""
        self.pace.see(now, track)
        if track is None or track.T_base_model is None:
            stop = "no target"
        elif (age := now - track.t + track.coast_s) > (limit := self.pace.limit_s(p)):  # coasting: measurement's age
            stop = f"estimate {1e3 * age:.0f} ms old (limit {1e3 * limit:.0f} ms)"
        T_des = None
        if not stop:
            if self.phase == "search":
                self._enter(now, "servo", f"creature {track.status} again, leaving the search pose")
            T_target, v_target = target_now(track, now)
            if np.linalg.norm(T_target[:3, 3] - np.array([0.0, 0.0, pa10.DH_D_MM[0]])) > REACH_MM:
                stop = "target out of reach"
            else:
                self._advance_collection(now, dt)
                T_des = desired_camera_pose(T_target, track.size_mm, self.height_mm, T_base_cam[:3, :3],
                                            self.T_left_centre)
        elif self.phase in ("descend", "grasp"):
            self._enter(now, "ascend", f"collection aborted ({stop}), climbing back")
            self.tool_on = False
        e_p = np.full(3, np.nan)
        yaw = float("nan")
        if T_des is not None:
            e = pose_error(T_des, T_base_cam)
            e_p = e[:3]
            yaw = yaw_error_deg(T_base_cam, T_des)
            self._update_hold(now, float(np.linalg.norm(e_p)), yaw)
            v, w = camera_twist(e, v_target, p)
            twist = flange_twist(v, w, T_base_cam[:3, 3], T_base_flange[:3, 3])
            dq_target = pa10.dls_step(q, twist, p.damping, k_null=0.5)
            sp = self.motion.velocity_step(q, dq, dq_target)
        elif self._searching(now, track):
            sp = self.motion.move_step(q, dq, self.search_q)
            stop = sp.reason or ("at the search pose" if self.motion.done else "to the search pose")
        else:
            sp = self.motion.stop_step(q, dq, reason=stop)
        return ControlInfo(now, self.phase, sp, T_base_cam, T_des, float(np.linalg.norm(e_p)), yaw,
                           stop or sp.reason, self.tool_on)

    def _searching(self, now: float, track: Track | None) -> bool:
        """No pose to servo on: go on to the search pose (or start for it when the tracker says
        the creature left the view, while servoing)?"""
        if self.search_q is None:
            return False
        if self.phase == "servo" and track is not None and track.status == "out_of_view":
            self._enter(now, "search", "creature out of view, moving to the search pose")
        return self.phase == "search"

    def _update_hold(self, now: float, err_mm: float, yaw_deg: float) -> None:
        p = self.params
        ok = err_mm <= p.hold_tolerance_mm and yaw_deg <= p.hold_tolerance_deg
        if not ok:
            self.t_hold_start = None
        elif self.t_hold_start is None:
            self.t_hold_start = now
        if (self.collect and self.phase == "servo" and self.t_hold_start is not None
                and now - self.t_hold_start >= p.hold_time_s and not self.collected):
            self._enter(now, "descend", f"holding within {p.hold_tolerance_mm:.0f} mm for {p.hold_time_s:.1f} s")

    def _advance_collection(self, now: float, dt: float) -> None:
        p = self.params
        if self.phase == "descend":
            self.height_mm = max(p.collect_height_mm, self.height_mm - p.collect_speed_mm_s * dt)
            if self.height_mm <= p.collect_height_mm:
                self.t_grasp, self.tool_on = now, True
                self._enter(now, "grasp", "at collection height, tool on")
        elif self.phase == "grasp":
            if now - self.t_grasp >= p.tool_dwell_s:
                self.collected = True
                self._enter(now, "ascend", "tool dwell over, with the catch")
        elif self.phase == "ascend":
            self.height_mm = min(p.hover_mm, self.height_mm + p.collect_speed_mm_s * dt)
            if self.height_mm >= p.hover_mm:
                done = self.collected
                self._enter(now, "done" if done else "servo", "collection complete" if done else "back at hover height")


def target_now(track: Track, now: float) -> tuple[np.ndarray, np.ndarray]:
    """The target's pose (4x4, base frame, mm) and velocity (mm/s) predicted from a track to the
    time `now` (s, the track's clock): constant velocity from its capture time, the height and
    vertical velocity from its heave when it has one (vision/heave.py: an oscillation, not a
    constant vertical velocity)."""
    dt = now - track.t
    T = track.T_base_model.copy()
    T[:3, 3] += track.velocity_mm_s * dt
    v = np.array(track.velocity_mm_s, dtype=float)
    if track.heave is not None:
        T[2, 3], v[2] = track.heave.z(dt), track.heave.vz(dt)
    return T, v


def phase_event(phase: Phase, why: str) -> str:
    """The event text of a change of collection phase, which `phase_of` reads back (the
    recording's events say when the controller servoed: servo/scores.scored_holds).

    >>> phase_of(phase_event("descend", "holding within 10 mm for 1.5 s"))
    'descend'
    """
    return f"phase {phase}: {why}"


def phase_of(text: str) -> Phase | None:
    """The phase an event text (`phase_event`) enters; None for any other event."""
    head, sep, _ = text.partition(": ")
    name = head.removeprefix("phase ")
    return name if sep and head.startswith("phase ") and name in PHASES else None  # type: ignore[return-value]


def search_joints(params: ServoParams, motion: Motion) -> np.ndarray | None:
    """[servo] search_pose_deg as joints (rad), checked against the joint ranges less
    joint_margin_deg and the keep-out (`Motion.check_target`): an InputError naming the key
    otherwise. None when the key is empty (no search pose)."""
    if not params.search_pose_deg:
        return None
    q = np.radians(np.asarray(params.search_pose_deg, dtype=float))
    try:
        motion.check_target(q)
    except InputError as e:
        shown = ", ".join(f"{v:g}" for v in params.search_pose_deg)
        raise InputError(f"config key 'servo.search_pose_deg' = [{shown}]: {str(e).removeprefix('target: ')}") from None
    return q


def left_centre(rig: Rig) -> np.ndarray:
    """Midpoint of the two optical centres in the left camera frame (mm)."""
    return -rig.R.T @ rig.T / 2.0
