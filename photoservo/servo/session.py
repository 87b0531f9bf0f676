"""The product loop (issue 5): frames -> tracker -> servo law -> Ruckig -> arm, with the recorder
listening on the side. Its body is written once and used by every run:

  * `vision_step`: one stereo frame through the tracker, counted, timed and recorded;
  * `control_tick`: one control period — the controller (servo/controller.py) on the measured
    joint state, the setpoint sent to the arm, the hold scored against the truth (simulation);
    it returns a `Tick`, which `log_tick` records;
  * `Status`: what the status line shows.

The runs that call them: the real-time session (servo/realtime.py: the control loop in its own
process, exchanging `Tick`s with the vision loop), the lockstep run on the simulator's clock
(sim/run.py) and replay (record/replay.py).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoservo.config import Config
from photoservo.robot import pa10
from photoservo.robot.arm import Arm
from photoservo.servo.controller import Controller, Phase, left_centre, search_joints
from photoservo.servo.motion import Motion
from photoservo.servo.scores import Scores, Truth
from photoservo.vision.fitness import StereoHue, stereo_hue
from photoservo.vision.rig import Rig
from photoservo.vision.track import Track
from photoservo.vision.tracker import Tracker

ARM_LOG_EVERY = 5  # control periods per logged arm sample (50 Hz at the 250 Hz control rate)


@dataclass(frozen=True)
class Frame:
    """A stereo frame in flight: captured at t_left/t_right, its track usable by the control
    law from t_delivery (s, session time); the left camera at T_base_left at t_left."""

    index: int
    t_left: float
    t_right: float
    t_delivery: float
    left: np.ndarray
    right: np.ndarray
    T_base_left: np.ndarray


@dataclass(frozen=True)
class Tick:
    """One control period, as the control process reports it to the vision process."""

    t: float                         # control time (s)
    t_state: float                   # time of the measured state (s)
    q: np.ndarray                    # measured joints (rad)
    setpoint_q: np.ndarray           # commanded joint positions (rad)
    setpoint_dq: np.ndarray          # commanded joint velocities (rad/s)
    T_base_cam_des: np.ndarray | None  # desired left-camera pose (mm), None when stopped
    phase: Phase
    error_mm: float                  # camera position error against the desired pose (from the ESTIMATE)
    yaw_deg: float                   # camera yaw error against the desired pose (deg)
    stop_reason: str
    events: tuple[tuple[float, str], ...] = ()
    link: Any = None                 # robot.link_quality.LinkQuality of the real-time link, if any


@dataclass(frozen=True)
class Status:
    """The live status line: the latest track and control tick."""

    t: float
    frames: int
    found: bool
    status: str
    fitness: float | None
    position_mm: np.ndarray | None
    alpha: float | None
    error_mm: float
    yaw_deg: float
    phase: str
    stop: str
    fps: float | None = None  # None on the simulated clock
    link: Any = None          # the link's quality (real time)
    truth_error_mm: float | None = None  # simulation: the track error against the truth (nan: no pose)

    @classmethod
    def of(cls, t: float, sc: Scores, track: Track | None, tick: Tick, fps: float | None = None) -> "Status":
        pos = None if track is None or track.T_base_model is None else track.T_base_model[:3, 3]
        return cls(t, sc.frames, bool(track and track.found), track.status if track else "acquiring",
                   None if track is None else track.fitness, pos, None if track is None else track.alpha,
                   tick.error_mm, tick.yaw_deg, tick.phase, tick.stop_reason, fps, tick.link,
                   sc.truth_frames[-1].error_mm if sc.truth_frames else None)


StatusFn = Callable[[Status], None]


# ----------------------------------------------------------------------------- the loop body


def vision_step(fr: Frame, tracker: Tracker, cfg: Config, sc: Scores, recorder, truth: Truth | None = None,
                events: list[tuple[float, str]] | None = None, max_generations: int | None = None,
                hue: StereoHue | None = None) -> Track:
    """One frame through the tracker (method step 5), timed, counted, scored against the `truth`
    (simulation: the hold at the frame's capture time) and recorded; a change of the track's
    status goes to `events` at fr.t_delivery. `max_generations`: Tracker.update.
    `hue`: the fitness input when it is known already (a replay of a compact recording);
    computed from the frame otherwise."""
    c0 = time.perf_counter()
    hue = stereo_hue(fr.left, fr.right, cfg.fitness) if hue is None else hue
    c1 = time.perf_counter()
    track = tracker.update(hue, fr.left, fr.right, fr.T_base_left, fr.t_left, max_generations)
    c2 = time.perf_counter()
    sc.time("hue", 1e3 * (c1 - c0))
    sc.time("ga", 1e3 * (c2 - c1))
    if sc.note_track(track.found, track.status) and events is not None:
        events.append((fr.t_delivery, f"track {track.status}"))
    if truth is not None:
        sc.score_hold(fr.t_left, fr.T_base_left, left_centre(tracker.rig), truth, cfg.servo.hover_mm)
        sc.score_track(truth, fr.T_base_left, fr.t_left, track.status,
                       None if track.T_base_model is None else track.T_base_model[:3, 3])
    if recorder is not None:
        _record_frame(recorder, fr, hue, track, truth, sc, {"hue": 1e3 * (c1 - c0), "ga": 1e3 * (c2 - c1)})
    return track


def _record_frame(recorder, fr: Frame, hue: StereoHue, track: Track, truth: Truth | None,
                  sc: Scores, timings: dict[str, float]) -> None:
    c3 = time.perf_counter()
    recorder.log_frame(fr.index, fr.t_left, fr.left, fr.right, T_base_left=fr.T_base_left,
                       capture_times=(fr.t_left, fr.t_right), fitness_input=hue)
    # the projected model points are drawn by the recorder (at the video's rate, from its model and rig)
    recorder.log_estimate(fr.index, fr.t_left, found=track.found, fitness=track.fitness,
                          R=track.R_left, position_mm=track.t_left, alpha=track.alpha_measured,
                          size_mm=track.size_mm, generations=track.generations, T_base_left=fr.T_base_left)
    if truth is not None:
        recorder.log_truth(fr.index, fr.t_left, truth.motion.pose(fr.t_left), truth.size_mm)
    sc.time("record", 1e3 * (time.perf_counter() - c3))
    recorder.log_timings(fr.t_left, {**timings, "record": sc.timings_ms["record"][-1]}, frame=fr.index)


@dataclass
class ControlLoop:
    """The control side's state across ticks: the controller, the arm it commands (None: open
    loop or --no-motion), the scores, and the truth (simulation) at scene time = now - t0 (t0
    None: the session's clock has not started, nothing is scored)."""

    ctrl: Controller
    arm: Arm | None
    scores: Scores
    truth: Truth | None = None
    t0: float | None = 0.0
    tool: bool = False
    n_events: int = 0


def control_tick(c: ControlLoop, now: float, t_state: float, q: np.ndarray, dq: np.ndarray,
                 track: Track | None) -> Tick:
    """One control period (method step 6) at time `now` (s) on the measured joints q (rad),
    dq (rad/s): the controller's step, the setpoint (and a tool switch) sent to the arm, the
    look-alike's distance scored against the truth, the phase events kept for the hold score
    (session time). Returns the period's `Tick`."""
    ctrl = c.ctrl
    info = ctrl.step(now, q, dq, track, t_state)
    if c.arm is not None:
        c.arm.send_setpoint(info.setpoint.q, info.setpoint.dq, now)
        if info.tool != c.tool:
            c.arm.tool(info.tool)
            c.tool = info.tool
    events = tuple(ctrl.events[c.n_events:])
    c.n_events = len(ctrl.events)
    if c.t0 is not None:
        if c.truth is not None:
            c.scores.score_distractor(now - c.t0, info.T_base_cam, ctrl.T_left_centre, c.truth)
        c.scores.note_events([(max(t_e - c.t0, 0.0), text) for t_e, text in events])
    return Tick(now, t_state, q, info.setpoint.q, info.setpoint.dq, info.T_base_cam_des, info.phase,
                info.position_error_mm, info.yaw_error_deg, info.stop_reason, events)


def log_tick(recorder, tick: Tick, i: int, t0: float = 0.0) -> None:
    """Record a tick's events, and every ARM_LOG_EVERY-th tick (i) the arm: measured q,
    setpoint_q (rad), setpoint_dq (rad/s), desired camera pose; times shifted by -t0 (an event
    from before t0 is recorded at 0)."""
    for t_e, text in tick.events:
        recorder.event(max(t_e - t0, 0.0), text)
    if i % ARM_LOG_EVERY == 0:
        recorder.log_arm(tick.t - t0, tick.q, tick.setpoint_q, tick.setpoint_dq)
        if tick.T_base_cam_des is not None:
            recorder.log_desired(tick.t - t0, tick.T_base_cam_des)


def controller_for(cfg: Config, rig: Rig, collect: bool = False) -> Controller:
    """The servo controller of a rig with [hand_eye] (the session's, the lockstep run's, replay's);
    InputError when [servo] search_pose_deg is out of the arm's limits or keep-out."""
    motion = Motion(cfg.motion, pa10.load_limits())
    return Controller(cfg.servo, motion, rig.T_flange_left(), left_centre(rig), collect=collect,
                      search_q=search_joints(cfg.servo, motion))
