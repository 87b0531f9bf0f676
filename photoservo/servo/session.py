"""The product loop (issue 5): frames -> tracker -> servo law -> Ruckig -> arm, with the recorder
listening on the side. Its body is written once and used by every run:

  * `vision_step`: one stereo frame through the tracker, counted, timed and recorded;
  * `control_tick`: one control period — the controller (servo/controller.py) on the measured
    joint state, the setpoint sent to the arm, the hold scored against the truth (simulation);
    it returns a `Tick`, which `log_tick` records;
  * `Status`: what the status line shows.

The runs that call them: `run_realtime` here (the control loop in its own process,
`control_process`, exchanging `Tick`s with the vision loop), the lockstep run on the simulator's
clock (sim/run.py) and replay (record/replay.py).
"""

from __future__ import annotations

import multiprocessing
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from photoservo.config import Config
from photoservo.robot import pa10
from photoservo.robot.arm import Arm, JointHistory
from photoservo.robot.clock import Rate, ignore_stop_signals, lower_priority, raise_priority, set_realtime, start_child
from photoservo.servo.controller import Controller, Phase, left_centre, search_joints
from photoservo.servo.motion import Motion
from photoservo.servo.scores import Scores, Truth
from photoservo.servo.warm import warm_kinematics, warm_start
from photoservo.vision.fitness import StereoHue, project_model, stereo_hue
from photoservo.vision.rig import Rig
from photoservo.vision.sources import StereoFrame
from photoservo.vision.tracker import Track, Tracker

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
class TickBatch:
    """ARM_LOG_EVERY control periods as the control process sends them to the vision process:
    the measured joint states of every period (for placing frames) and the last period's `Tick`,
    carrying the events of all of them. One message per batch instead of one per period: at
    250 Hz, pickling a Tick a period cost the control process a fifth of its CPU, and each
    message woke the vision process's receiver thread, which then took the GIL from the vision
    work."""

    t_state: np.ndarray  # (n,) times of the measured states (monotonic s)
    q: np.ndarray        # (n, 7) measured joints (rad)
    tick: Tick


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
        _record_frame(recorder, fr, hue, track, tracker, truth, sc, {"hue": 1e3 * (c1 - c0), "ga": 1e3 * (c2 - c1)})
    return track


def _record_frame(recorder, fr: Frame, hue: StereoHue, track: Track, tracker: Tracker, truth: Truth | None,
                  sc: Scores, timings: dict[str, float]) -> None:
    c3 = time.perf_counter()
    recorder.log_frame(fr.index, fr.t_left, fr.left, fr.right, T_base_left=fr.T_base_left,
                       capture_times=(fr.t_left, fr.t_right), fitness_input=hue)
    proj = None
    if track.R_left is not None:
        proj = project_model(track.R_left[None], track.t_left[None], np.array([track.alpha_measured]),
                             tracker.model, tracker.rig)
    recorder.log_estimate(fr.index, fr.t_left, found=track.found, fitness=track.fitness,
                          R=track.R_left, position_mm=track.t_left, alpha=track.alpha_measured,
                          size_mm=track.size_mm, generations=track.generations,
                          T_base_left=fr.T_base_left, projection=proj)
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
    info = ctrl.step(now, q, dq, track)
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


# ----------------------------------------------------------------------------- real time


@dataclass(frozen=True)
class ControlJob:
    """What the control process needs, picklable (it starts with `spawn`)."""

    cfg: Config
    port: str
    rig: Rig
    collect: bool
    no_motion: bool
    truth: Truth | None  # simulation: scores the hold against the true target
    t0: float | None  # None: sent as ("t0", t) once the session's clock starts
    rt_priority: int | None  # None: best effort (raise_priority), N: SCHED_FIFO N or an event saying why not
    simulated: bool = False  # the bridge is the simulator's emulator (errors speak of it)


#: SCHED_FIFO priority the control process asks for when no --rt-priority is given (below the
#: simulator's bridge, sim/emulator_process.py, which it waits on)
CONTROL_RT_PRIORITY = 20
#: niceness of the session's other processes and threads (vision, renderer, video encoder) when the
#: control process got no real-time class: ~1/10 of the CPU against the control loop and the bridge
#: (non-root, load 8-15, `track --sim`: control lateness medians 0.5-4.8 ms -> 0.08-0.16 ms).
BACKGROUND_NICE = 10


def control_process(job: ControlJob, conn, stop) -> None:
    """The control loop in its own process (issue 3's measurements: a thread next to the vision
    work cannot hold 250 Hz on 2 cores; a process with SCHED_FIFO can): owns the link, runs
    `control_tick` at the control rate, takes tracks from `conn`, sends back each `Tick`, and
    ends — on `stop`, a fault or an exception — with a controlled stop and the servo off. Its
    last message is ("done", Scores)."""
    from photoservo.robot.link import Link

    # Ctrl-C (and SIGTERM, SIGHUP) may reach the whole process group: the vision process handles
    # it and sets `stop`, so this loop ends in order (controlled stop, servo off)
    ignore_stop_signals()
    warm_kinematics()  # loaded from numba's cache (the session's warm start compiled it) before the first period
    cfg = job.cfg
    c = ControlLoop(controller_for(cfg, job.rig, job.collect), None, Scores(settle_s=cfg.servo.settle_s), job.truth, job.t0)
    realtime = False
    try:
        if job.rt_priority is not None:
            try:
                set_realtime(job.rt_priority)
                realtime = True
            except OSError as e:  # not a fault: the loop runs, only less steadily (events say so)
                c.ctrl.events.append((time.monotonic(), f"real-time priority {job.rt_priority} refused "
                                                        f"({e.strerror}); control runs without it"))
        else:  # a busy machine must not starve the arm's loop: the best the system permits
            got = raise_priority(CONTROL_RT_PRIORITY)
            realtime = got.startswith("SCHED_FIFO")
            c.ctrl.events.append((time.monotonic(), f"control process scheduling: {got}"))
        with Link(job.port, cfg.link, simulated=job.simulated) as link:
            link.wait_state()
            if not job.no_motion:
                link.enable()
                c.arm = link
            conn.send(("ready", realtime))
            rate = Rate(cfg.motion.rate_hz)
            track = None
            batch: list[Tick] = []
            try:
                while not stop.is_set():
                    now = time.monotonic()
                    while conn.poll():
                        msg = conn.recv()
                        if isinstance(msg, tuple):  # ("t0", t): the session's clock started
                            c.t0 = msg[1]
                        else:
                            track = msg
                    st = link.state()
                    batch.append(control_tick(c, now, st.t, st.q, st.dq, track))
                    if len(batch) == ARM_LOG_EVERY:
                        conn.send(_batch(batch, link.quality()))
                        batch.clear()
                    c.scores.time("control_ms", 1e3 * (time.monotonic() - now))
                    c.scores.time("control_late", 1e3 * rate.sleep())
            finally:
                if batch:  # the last periods' states and events (fewer than a batch); never before the stop
                    try:
                        conn.send(_batch(batch, link.quality()))
                    except (OSError, ValueError):
                        pass
                if not job.no_motion:
                    controlled_stop(link, c.scores)
    except Exception as e:  # noqa: BLE001 - a fault while moving: the arm is stopped, then reported
        c.scores.faults.append(f"{type(e).__name__}: {e}")
    finally:
        c.scores.collected = c.ctrl.collected
        try:
            conn.send(("done", c.scores))
        except (OSError, ValueError):
            pass


def _batch(ticks: list[Tick], link_quality) -> TickBatch:
    """The periods `ticks` as one message: their states, the last tick with all their events."""
    events = tuple(e for tk in ticks for e in tk.events)
    return TickBatch(np.array([tk.t_state for tk in ticks]), np.array([tk.q for tk in ticks]),
                     replace(ticks[-1], events=events, link=link_quality))


class _ControlProcess:
    """The vision process's end of `control_process`: starts it, receives its ticks (joint
    states into `history`, the latest tick, the records), sends tracks, and stops it."""

    def __init__(self, job: ControlJob, recorder, stop: threading.Event) -> None:
        ctx = multiprocessing.get_context("spawn")
        self.conn, child = ctx.Pipe()
        self.child_stop = ctx.Event()
        self.proc = ctx.Process(target=control_process, args=(job, child, self.child_stop),
                                name="photoservo-control", daemon=True)
        start_child(self.proc)
        self.t0, self.recorder, self.stop = job.t0, recorder, stop
        self.history = JointHistory(keep_s=2.0, ahead_s=0.01)
        self.pending: list[tuple[float, str]] = []  # events from before the session's clock (t0) starts
        self.latest: Tick | None = None
        self.ready = False
        self.realtime = False  # the control process got a real-time scheduling class
        self.scores: Scores | None = None
        self.rx = threading.Thread(target=self._receive, name="control-rx", daemon=True)
        self.rx.start()

    def _receive(self) -> None:
        """Drain the control process's messages: tick batches, 'ready', the result."""
        while True:
            try:
                msg = self.conn.recv()
            except (EOFError, OSError):
                return
            if isinstance(msg, TickBatch):
                for t_state, q in zip(msg.t_state, msg.q):
                    self.history.append(float(t_state), q)
                tick = self.latest = msg.tick
                t0 = self.t0
                if self.recorder is not None and t0 is None:  # "ready" came, the clock is about to start
                    self.pending.extend(tick.events)
                elif self.recorder is not None:  # the batch's last tick is the logged arm sample
                    log_tick(self.recorder, replace(tick, events=(*self.pending, *tick.events)), 0, t0)
                    self.pending.clear()
            elif msg[0] == "ready":
                self.realtime = msg[1]
                self.ready = True
            elif msg[0] == "done":
                self.scores = msg[1]
                self.stop.set()
                return

    def wait_ready(self, timeout_s: float = 30.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not self.ready and not self.stop.is_set():  # the process imports, opens the link
            if time.monotonic() > deadline:
                raise RuntimeError(f"the control process did not start within {timeout_s:.0f} s")
            time.sleep(0.01)

    def joints_at(self, t: float, wait_s: float = 0.05) -> np.ndarray:
        """The measured joints (rad) at monotonic time t. The states come in batches of
        ARM_LOG_EVERY periods, so a frame captured within the last one waits (up to wait_s) for
        the batch that covers it. Raises LookupError when there is none."""
        deadline = time.monotonic() + wait_s
        while self.history.span[1] < t and time.monotonic() < deadline and self.rx.is_alive():
            time.sleep(0.002)
        return self.history.at(t)[0]

    def step_back(self, keep_ids: frozenset[int]) -> list[tuple[float, str]]:
        """When the control process got no real-time class: this process, its threads and its
        other child processes step back (`lower_priority` to BACKGROUND_NICE), except the
        control process and `keep_ids` (the simulator's bridge). Returns the event saying so
        (session time 0), or none."""
        if self.realtime:
            return []
        done = lower_priority(BACKGROUND_NICE, keep={self.proc.pid, *keep_ids})
        return [(0.0, f"control process without real-time priority: the rest of the session steps back ({done})")]

    def send(self, msg: Track | tuple) -> bool:
        """Send a track (or the clock's start); False when the control process has ended."""
        try:
            self.conn.send(msg)
        except (BrokenPipeError, EOFError, OSError):
            return False
        return True

    def start_clock(self, t0: float) -> None:
        """The session's clock starts at t0 (monotonic s): the control process scores from it. If
        it has ended already (a fault as it started), the session stops; its report says why."""
        self.t0 = t0
        if not self.send(("t0", t0)):
            self.stop.set()

    def close(self) -> Scores | None:
        """Stop the process; its scores (None: it ended without a report)."""
        self.child_stop.set()
        self.rx.join(timeout=10.0)
        self.proc.join(timeout=5.0)
        if self.proc.is_alive():  # it ignores SIGTERM (ignore_stop_signals)
            self.proc.kill()
        return self.scores


def run_realtime(cfg: Config, duration_s: float, *, port: str, read_frame: Callable[[], StereoFrame | None],
                 model, rig: Rig, collect: bool = False, no_motion: bool = False, recorder=None,
                 status: StatusFn | None = None, seed: int = 0, truth: Truth | None = None,
                 t0: float | None = None, rt_priority: int | None = None,
                 stop_event: threading.Event | None = None, simulated: bool = False,
                 start_clock: Callable[[], float] | None = None, say: Callable[[str], None] | None = None,
                 keep_ids: frozenset[int] = frozenset()) -> Scores:
    """The real-time session. The control loop (`control_process`) runs in its own process,
    connected to the bridge at `port`; this process reads stereo frames (`read_frame()`, capture
    times on the monotonic clock), places each at the joint state of its capture time (streamed
    back by the control process), runs `vision_step` and sends each track over. Stopping
    (duration, Ctrl-C, an error here or a fault there) ends with the arm stopped and the servo
    off. `truth` (simulation) scores the hold.
    The kernels are warmed first (`warm_start`; `say` gets its notice on a first run) and the
    session's clock starts once the control process is ready: at t0, or at what `start_clock()`
    returns then (the simulator starts its cameras and world there), else when it is ready.
    `keep_ids`: processes or threads that must hold their period too (`_ControlProcess.step_back`)."""
    T_fl = rig.T_flange_left()
    controller_for(cfg, rig, collect)  # its config checked here (exit 2), before the control process starts
    warm_start(model, rig, cfg.fitness, say=say)  # before the arm is enabled (no-op when warmed already)
    tracker = Tracker.from_config(model, rig, cfg, seed=seed)
    sc = Scores(settle_s=cfg.servo.settle_s)
    stop = stop_event or threading.Event()
    control = _ControlProcess(ControlJob(cfg, port, rig, collect, no_motion, truth, t0, rt_priority,
                                         simulated), recorder, stop)
    events: list[tuple[float, str]] = []
    try:
        control.wait_ready()
        events += control.step_back(keep_ids)
        if t0 is None:  # the clock starts now: the arm is enabled, the kernels are warm
            t0 = start_clock() if start_clock is not None else time.monotonic()
            control.start_clock(t0)
        while not stop.is_set() and time.monotonic() - t0 < duration_s:
            c0 = time.perf_counter()
            got = read_frame()
            if got is None:
                continue
            sc.time("capture", 1e3 * (time.perf_counter() - c0))
            try:
                T_l = pa10.fk(control.joints_at(got.t_left)) @ T_fl
            except LookupError as e:  # no arm state for the capture time: cannot place the frame
                sc.dropped_frames += 1
                if recorder is not None and sc.dropped_frames == 1:
                    recorder.event(time.monotonic() - t0, f"frame dropped: {e}")
                continue
            fr = Frame(got.index, got.t_left - t0, got.t_right - t0, time.monotonic() - t0, got.left, got.right, T_l)
            track = vision_step(fr, tracker, cfg, sc, recorder, truth, events)
            if not control.send(replace(track, t=track.t + t0)):  # the control process reads monotonic time
                break  # it has ended (its report says why)
            for t_e, text in events:
                if recorder is not None:
                    recorder.event(t_e, text)
            events.clear()
            sc.time("frame", 1e3 * (time.perf_counter() - c0))
            if status is not None and control.latest is not None:
                status(Status.of(time.monotonic() - t0, sc, track, control.latest,
                                 1e3 / float(np.median(sc.timings_ms["frame"][-30:]))))
    finally:
        _merge_control_scores(sc, control.close())
        sc.acquisitions = tracker.acquisitions
    return sc


def _merge_control_scores(sc: Scores, ctl: Scores | None) -> None:
    """The control process's part of the scores (faults, collection, hold, its timings)."""
    if ctl is None:
        sc.faults.append("the control process ended without a report (the bridge watchdog stops the arm)")
        return
    sc.faults += ctl.faults
    sc.collected = ctl.collected
    sc.phase_events = ctl.phase_events
    sc.distractor_min_mm = ctl.distractor_min_mm
    sc.timings_ms.update(ctl.timings_ms)


def controlled_stop(arm, sc: Scores) -> None:
    """Stop the arm in a controlled way and switch the servo off; a link that is already gone
    leaves the bridge's own watchdog to stop it (noted as a fault)."""
    try:
        arm.stop()
        arm.wait_until_still(timeout=3.0)
        arm.disable()
    except Exception as e:  # noqa: BLE001
        sc.faults.append(f"controlled stop via the link failed ({e}); the bridge watchdog stops the arm")
