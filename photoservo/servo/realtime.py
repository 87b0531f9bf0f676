"""The real-time session (issue 5): the control loop in its own process (`control_process`, at
the control rate on the bridge's link, SCHED_FIFO when permitted) and the vision loop in this one
(`run_realtime`: frames -> `vision_step` -> tracks to the control process), exchanging tracks one
way and `TickBatch`es of measured joint states and events the other. The loop bodies
(`vision_step`, `control_tick`) are those of servo/session.py, which the lockstep run and replay
use too.
"""

from __future__ import annotations

import multiprocessing
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from photoservo.config import Config
from photoservo.robot import pa10
from photoservo.robot.arm import JointHistory
from photoservo.robot.clock import (Rate, freeze_heap, ignore_stop_signals, lower_priority, raise_priority, set_realtime,
                                    start_child)
from photoservo.servo.scores import Scores, Truth
from photoservo.servo.session import (ARM_LOG_EVERY, ControlLoop, Frame, Status, StatusFn, Tick, control_tick,
                                      controller_for, log_tick, vision_step)
from photoservo.servo.warm import warm_kinematics, warm_start
from photoservo.vision.rig import Rig
from photoservo.vision.sources import StereoFrame
from photoservo.vision.track import Track
from photoservo.vision.tracker import Tracker


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
    frozen = freeze_heap()  # before the link and the arm: no full collection over the imported libraries in the loop
    c.ctrl.events.append((time.monotonic(), f"control process heap: {frozen} objects frozen before the loop"))
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
        freeze_heap()  # the warm start's and the libraries' objects: no full collection over them per frame
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
            sc.note_delivery(time.monotonic() - t0, track.status)
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
