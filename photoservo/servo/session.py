"""The tracking session (issue 5): frames -> tracker -> servo law -> Ruckig -> link -> arm, with
the recorder listening on the side.

Two clocks, one code path for the control law:
  * lockstep (`run_lockstep`): the simulator's clock. Control ticks at the control rate, camera
    frames at the camera rate, each frame processed when it is delivered (capture + latency);
    the arm is the emulator's bridge clocked by the simulation (world.LockstepArm). Deterministic.
  * real time (`run_realtime`): time.monotonic. A control thread at the control rate (Rate) reads
    the link's latest state, the latest track, and streams setpoints; the main thread captures
    frames (real cameras, or the simulator rendering from the arm's interpolated state at each
    exposure time) and runs the tracker.

Collection (`--collect`) is a small state machine in `Controller`:
  servo --(hold error within tolerance for hold_time_s)--> descend --(at collect height)-->
  grasp (tool on, dwell) --> ascend --(back at hover)--> done; any loss of the target while
  descending aborts: climb back to hover height (tool off) and servo again.
"""

from __future__ import annotations

import dataclasses
import math
import multiprocessing
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Callable, Literal

import numpy as np

from photoservo.robot import pa10
from photoservo.robot.arm import JointHistory
from photoservo.geometry import make_pose, pose_error
from photoservo.robot import protocol as P
from photoservo.robot.clock import Rate, ignore_stop_signals, raise_priority, set_realtime, start_child
from photoservo.config import Config
from photoservo.servo.control import (
    ServoParams,
    camera_twist,
    desired_camera_pose,
    flange_twist,
    yaw_error_deg,
)
from photoservo.servo.motion import Motion, Setpoint
from photoservo.sim.world import LockstepArm, SimScene, TargetMotion, sim_hand_eye
from photoservo.vision.fitness import StereoHue, project_model, stereo_hue
from photoservo.vision.rig import Rig
from photoservo.sim.scenes import synthetic_rig
from photoservo.vision.tracker import Track, Tracker
from photoservo.servo.warm import warm_start

Phase = Literal["servo", "descend", "grasp", "ascend", "done", "stopped"]
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


@dataclass
class Controller:
    """One control period of position-based visual servoing (servo/control.py) on the PA-10:
    camera twist -> flange twist -> joint velocities by damped least squares (robot/pa10.py,
    null space pulled toward HOME_Q) -> Ruckig velocity interface with the safety layer
    (servo/motion.py). A controlled stop when the track is missing or older than
    max_estimate_age_s, or the target leaves the reachable workspace."""

    params: ServoParams
    motion: Motion
    T_flange_left: np.ndarray
    T_left_centre: np.ndarray
    collect: bool = False
    phase: Phase = "servo"
    height_mm: float = field(default=0.0)
    t_hold_start: float | None = None
    t_grasp: float | None = None
    tool_on: bool = False
    collected: bool = False
    events: list[tuple[float, str]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.height_mm = self.params.hover_mm

    def _event(self, t: float, text: str) -> None:
        self.events.append((t, text))

    def step(self, now: float, q: np.ndarray, dq: np.ndarray, track: Track | None) -> ControlInfo:
        p = self.params
        dt = self.motion.dt
        T_base_flange = pa10.fk(q)
        T_base_cam = T_base_flange @ self.T_flange_left
        stop = ""
        if track is None or track.T_base_model is None:
            stop = "no target"
        elif now - track.t > p.max_estimate_age_s:
            stop = f"estimate {1e3 * (now - track.t):.0f} ms old"
        T_des = None
        if not stop:
            T_target = track.T_base_model.copy()
            T_target[:3, 3] += track.velocity_mm_s * (now - track.t)
            if np.linalg.norm(T_target[:3, 3] - np.array([0.0, 0.0, pa10.DH_D_MM[0]])) > REACH_MM:
                stop = "target out of reach"
            else:
                self._advance_collection(now, dt)
                T_des = desired_camera_pose(T_target, track.size_mm, self.height_mm, T_base_cam[:3, :3],
                                            self.T_left_centre)
        elif self.phase in ("descend", "grasp"):
            self._event(now, f"collection aborted: {stop}; climbing back")
            self.phase, self.tool_on = "ascend", False
        e_p = np.full(3, np.nan)
        yaw = float("nan")
        if T_des is not None:
            e = pose_error(T_des, T_base_cam)
            e_p = e[:3]
            yaw = yaw_error_deg(T_base_cam, T_des)
            self._update_hold(now, float(np.linalg.norm(e_p)), yaw)
            v, w = camera_twist(e, track.velocity_mm_s, p)
            twist = flange_twist(v, w, T_base_cam[:3, 3], T_base_flange[:3, 3])
            dq_target = pa10.dls_step(q, twist, p.damping, k_null=0.5)
            sp = self.motion.velocity_step(q, dq, dq_target)
        else:
            sp = self.motion.stop_step(q, dq, reason=stop)
        return ControlInfo(now, self.phase, sp, T_base_cam, T_des, float(np.linalg.norm(e_p)), yaw,
                           stop or sp.reason, self.tool_on)

    def _update_hold(self, now: float, err_mm: float, yaw_deg: float) -> None:
        p = self.params
        ok = err_mm <= p.hold_tolerance_mm and yaw_deg <= p.hold_tolerance_deg
        if not ok:
            self.t_hold_start = None
        elif self.t_hold_start is None:
            self.t_hold_start = now
        if (self.collect and self.phase == "servo" and self.t_hold_start is not None
                and now - self.t_hold_start >= p.hold_time_s and not self.collected):
            self.phase = "descend"
            self._event(now, f"holding within {p.hold_tolerance_mm:.0f} mm for {p.hold_time_s:.1f} s: descending")

    def _advance_collection(self, now: float, dt: float) -> None:
        p = self.params
        if self.phase == "descend":
            self.height_mm = max(p.collect_height_mm, self.height_mm - p.collect_speed_mm_s * dt)
            if self.height_mm <= p.collect_height_mm:
                self.phase, self.t_grasp, self.tool_on = "grasp", now, True
                self._event(now, "at collection height: tool on")
        elif self.phase == "grasp":
            if now - self.t_grasp >= p.tool_dwell_s:
                self.phase = "ascend"
                self.collected = True
                self._event(now, "tool dwell over: ascending with the catch")
        elif self.phase == "ascend":
            self.height_mm = min(p.hover_mm, self.height_mm + p.collect_speed_mm_s * dt)
            if self.height_mm >= p.hover_mm:
                self.phase = "done" if self.collected else "servo"
                self._event(now, "collection complete" if self.collected else "back at hover height")


def left_centre(rig) -> np.ndarray:
    """Midpoint of the two optical centres in the left camera frame (mm)."""
    return -rig.R.T @ rig.T / 2.0


StatusFn = Callable[[dict], None]


# ----------------------------------------------------------------------------- scoring


@dataclass
class Scores:
    """Per-run numbers: hold accuracy against the TRUE desired pose (simulation), tracking."""

    frames: int = 0
    found: int = 0
    lost_events: int = 0
    acquisitions: int = 0
    err_sq: list[float] = field(default_factory=list)  # position error^2 vs truth, t >= settle_s
    yaw_sq: list[float] = field(default_factory=list)
    max_err_mm: float = 0.0
    timings_ms: dict[str, list[float]] = field(default_factory=dict)
    collected: bool = False
    faults: list[str] = field(default_factory=list)
    distractor_min_mm: float = float("inf")  # closest the cameras' hover point came to the look-alike
    dropped_frames: int = 0  # frames with no arm state at their capture time

    def time(self, stage: str, ms: float) -> None:
        self.timings_ms.setdefault(stage, []).append(ms)

    def summary(self) -> dict:
        rms = math.sqrt(float(np.mean(self.err_sq))) if self.err_sq else float("nan")
        yaw = math.sqrt(float(np.mean(self.yaw_sq))) if self.yaw_sq else float("nan")
        return {
            "frames": self.frames, "found_ratio": self.found / max(1, self.frames),
            "lost_events": self.lost_events, "acquisitions": self.acquisitions,
            "dropped_frames": self.dropped_frames,
            "rms_position_error_mm": rms, "rms_yaw_error_deg": yaw, "max_position_error_mm": self.max_err_mm,
            "collected": self.collected, "faults": list(self.faults),
            "timings_ms_median": {k: float(np.median(v)) for k, v in self.timings_ms.items()},
            "distractor_min_mm": self.distractor_min_mm,
        }


# ----------------------------------------------------------------------------- the simulator run


@dataclass
class SimSetup:
    """Everything the simulated session starts from."""

    rig: Rig
    scene: SimScene
    limits: pa10.PA10Limits
    q0: np.ndarray  # arm start: start_offset_mm and start_yaw_deg off the desired pose


def sim_config(cfg: Config) -> Config:
    """The simulator's config: its water plane is known, so the tracker's plausibility gates use
    it ([tracker] water_z_mm = [sim] water_z_mm unless set)."""
    if math.isfinite(cfg.tracker.water_z_mm):
        return cfg
    return dataclasses.replace(cfg, tracker=dataclasses.replace(cfg.tracker, water_z_mm=cfg.sim.water_z_mm))


def build_sim(cfg: Config) -> SimSetup:
    """The simulated rig (synthetic_rig with the simulator's hand-eye), scene and arm start."""
    base = synthetic_rig()
    rig = Rig(base.left, base.right, base.R, base.T, hand_eye=sim_hand_eye(base))
    scene = SimScene(cfg.sim, cfg.photo_model, rig)
    limits = pa10.load_limits()
    T_fl = rig.T_flange_left()
    centre = left_centre(rig)
    T_des = desired_camera_pose(scene.motion.pose(0.0), scene.size_mm(), cfg.servo.hover_mm,
                                np.diag([-1.0, 1.0, -1.0]), centre)
    yaw = math.radians(cfg.sim.start_yaw_deg)
    Rz = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1.0]])
    c_des = T_des[:3, :3] @ centre + T_des[:3, 3]  # rig centre over the target
    R0 = Rz @ T_des[:3, :3]
    c0 = c_des + np.array([-cfg.sim.start_offset_mm, 0.0, 0.0])
    T_cam0 = make_pose(R0, c0 - R0 @ centre)
    q0 = pa10.ik(T_cam0 @ np.linalg.inv(T_fl), pa10.HOME_Q, limits)
    return SimSetup(rig, scene, limits, q0)


@dataclass
class Frame:
    """A stereo frame in flight: captured at t_left/t_right, delivered at t_delivery."""

    index: int
    t_left: float
    t_right: float
    t_delivery: float
    left: np.ndarray
    right: np.ndarray
    T_base_left: np.ndarray  # left camera at t_left (from the arm's state then)


def run_lockstep(cfg: Config, duration_s: float, *, collect: bool = False, no_motion: bool = False,
                 recorder=None, status: StatusFn | None = None, seed: int = 0,
                 settle_s: float = 5.0, setup: SimSetup | None = None,
                 say: Callable[[str], None] | None = None) -> Scores:
    """A simulated session on the simulator's clock (deterministic). Returns the scores; hold
    accuracy is measured against the desired pose of the TRUE target from `settle_s` on.
    `say` gets the warm start's one-line notice of a first run."""
    cfg = sim_config(cfg)
    sim = setup or build_sim(cfg)
    rig, scene = sim.rig, sim.scene
    warm_start(scene.model, rig, cfg.fitness, scene=scene, say=say)
    T_fl = rig.T_flange_left()
    centre = left_centre(rig)
    arm = LockstepArm(cfg.emulator, sim.limits, sim.q0)
    if not no_motion:
        arm.enable()
    ctrl = Controller(cfg.servo, Motion(cfg.motion, sim.limits), T_fl, centre, collect=collect)
    tracker = Tracker.from_config(scene.model, rig, cfg, seed=seed, time_budget=False)  # deterministic
    sc = Scores()
    dt = 1.0 / cfg.motion.rate_hz
    frame_dt = 1.0 / cfg.sim.camera_fps
    n_ticks = int(round(duration_s / dt))
    next_capture, k = 0.0, 0
    in_flight: list[Frame] = []
    track: Track | None = None
    prev_status = None
    tool = False
    n_events = 0
    for i in range(n_ticks):
        now = i * dt
        while next_capture <= now + 1e-9:
            t_l, t_r = next_capture, next_capture + cfg.sim.lr_skew_s
            T_l = pa10.fk(arm.state_at(t_l).q) @ T_fl
            T_r = pa10.fk(arm.state_at(min(t_r, now)).q) @ T_fl
            c0 = time.perf_counter()
            left, right = scene.render(T_l, t_l, T_r, t_r)
            sc.time("render", 1e3 * (time.perf_counter() - c0))
            in_flight.append(Frame(k, t_l, t_r, t_l + cfg.sim.capture_latency_s, left, right, T_l))
            k += 1
            next_capture = k * frame_dt
        while in_flight and in_flight[0].t_delivery <= now + 1e-9:
            fr = in_flight.pop(0)
            track = _vision_step(fr, tracker, cfg, sc, recorder, scene)
            if track.status != prev_status:
                if track.status == "lost":
                    sc.lost_events += 1
                ctrl.events.append((fr.t_delivery, f"track {track.status}"))
                prev_status = track.status
        st = arm.state()
        c0 = time.perf_counter()
        info = ctrl.step(now, st.q, st.dq, track)
        sc.time("control", 1e3 * (time.perf_counter() - c0))
        if not no_motion:
            arm.send_setpoint(info.setpoint.q, info.setpoint.dq, now)
            if info.tool != tool:
                arm.tool(info.tool)
                tool = info.tool
        while n_events < len(ctrl.events):
            t_e, text = ctrl.events[n_events]
            if recorder is not None:
                recorder.event(t_e, text)
            n_events += 1
        _score_hold(sc, ctrl, scene, info, now, settle_s, centre)
        if recorder is not None and i % 5 == 0:
            recorder.log_arm(now, st.q, info.setpoint.q, info.setpoint.dq)
            if info.T_base_cam_des is not None:
                recorder.log_desired(now, info.T_base_cam_des)
        if status is not None and i % int(round(0.5 / dt)) == 0:
            status(_status_dict(now, sc, track, info))
        arm.tick(now + dt)
    sc.collected = ctrl.collected
    sc.acquisitions = tracker.acquisitions
    sc.faults += [f"bridge refused setpoint: {P.Error(n.error).name}" for n in arm.nacks]
    return sc


def _vision_step(fr: Frame, tracker: Tracker, cfg: Config, sc: Scores, recorder, scene: SimScene | None,
                 max_generations: int | None = None, hue: StereoHue | None = None) -> Track:
    """One frame through the tracker, timed and recorded (`max_generations`: Tracker.update).
    `hue`: the fitness input when it is known already (a replay of a compact recording);
    computed from the frame otherwise."""
    c0 = time.perf_counter()
    hue = stereo_hue(fr.left, fr.right, cfg.fitness) if hue is None else hue
    c1 = time.perf_counter()
    track = tracker.update(hue, fr.left, fr.right, fr.T_base_left, fr.t_left, max_generations)
    c2 = time.perf_counter()
    sc.time("hue", 1e3 * (c1 - c0))
    sc.time("ga", 1e3 * (c2 - c1))
    sc.frames += 1
    sc.found += int(track.found)
    if recorder is not None:
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
        if scene is not None:
            recorder.log_truth(fr.index, fr.t_left, scene.motion.pose(fr.t_left), scene.size_mm())
        sc.time("record", 1e3 * (time.perf_counter() - c3))
        recorder.log_timings(fr.t_left, {"hue": 1e3 * (c1 - c0), "ga": 1e3 * (c2 - c1),
                                         "record": sc.timings_ms["record"][-1]}, frame=fr.index)
    return track


def _score_hold(sc: Scores, ctrl: Controller, scene: SimScene, info: ControlInfo, now: float,
                settle_s: float, centre: np.ndarray) -> None:
    """Camera pose error against the desired pose of the TRUE target (simulation only); `now`
    is scene time (s)."""
    _score_hold_truth(sc, ctrl, scene.motion, scene.size_mm(), info, now, settle_s, centre, scene.distractor_motion)


def _score_hold_truth(sc: Scores, ctrl: Controller, motion: TargetMotion, size_mm: tuple[float, float],
                      info: ControlInfo, now: float, settle_s: float, centre: np.ndarray,
                      distractor: TargetMotion | None = None) -> None:
    T_des = desired_camera_pose(motion.pose(now), size_mm, ctrl.height_mm, info.T_base_cam[:3, :3], centre)
    e_p = pose_error(T_des, info.T_base_cam)[:3]
    if distractor is not None:
        c = info.T_base_cam[:3, :3] @ centre + info.T_base_cam[:3, 3]
        d = distractor.pose(now)[:3, 3]
        sc.distractor_min_mm = min(sc.distractor_min_mm, float(np.linalg.norm((c - d)[:2])))
    if now >= settle_s and ctrl.phase == "servo":
        err = float(np.linalg.norm(e_p))
        sc.err_sq.append(err * err)
        sc.yaw_sq.append(yaw_error_deg(info.T_base_cam, T_des) ** 2)
        sc.max_err_mm = max(sc.max_err_mm, err)


def _status_dict(now: float, sc: Scores, track: Track | None, info: ControlInfo) -> dict:
    pos = None if track is None or track.T_base_model is None else track.T_base_model[:3, 3]
    return {"t": now, "frames": sc.frames, "found": bool(track and track.found),
            "status": track.status if track else "acquiring",
            "fitness": None if track is None else track.fitness,
            "position_mm": pos, "alpha": None if track is None else track.alpha,
            "error_mm": info.position_error_mm, "yaw_deg": info.yaw_error_deg, "phase": info.phase,
            "stop": info.stop_reason}


# ----------------------------------------------------------------------------- real time


def _render_process(cfg: Config, requests, frames) -> None:
    """The simulated cameras' renderer in its own process (its own core): builds the same scene
    as the session (`build_sim`, deterministic from the config) and renders each request
    (t_left, t_right, T_base_left, T_base_left_at_right) into a stereo pair."""
    ignore_stop_signals()  # the session stops it
    scene = build_sim(cfg).scene
    scene.warm()  # compile or load the renderer's kernel before the session's clock starts
    frames.send(("ready",))
    while True:
        try:
            msg = requests.recv()
        except (EOFError, OSError):  # the session process is gone
            return
        if msg is None:
            return
        frames.send(scene.render(*msg))



class SimCameras:
    """The simulator's stereo cameras in real time, like a camera with its own electronics: a
    shutter thread exposes a pair at the camera rate — the time is the monotonic clock then, the
    pose where the emulated arm truly is (its bridge's joint state) — and a renderer process
    delivers the images while the loop is busy with the previous pair. One exposure is in flight
    at a time; the loop learns where the cameras were from the arm's states, as on hardware."""

    def __init__(self, cfg: Config, emulator, T_flange_left: np.ndarray) -> None:
        self.emulator, self.T_fl, self.t0 = emulator, T_flange_left, 0.0
        self.period, self.skew = 1.0 / cfg.sim.camera_fps, cfg.sim.lr_skew_s
        ctx = multiprocessing.get_context("spawn")
        self._req_rx, self._req_tx = ctx.Pipe(duplex=False)
        self._frm_rx, self._frm_tx = ctx.Pipe(duplex=False)
        self._proc = ctx.Process(target=_render_process, args=(cfg, self._req_rx, self._frm_tx),
                                 name="photoservo-cameras", daemon=True)
        start_child(self._proc)  # it compiles or loads its kernel meanwhile: see wait_ready
        self._cond = threading.Condition()
        self._in_flight: deque[tuple[int, float]] = deque()
        self._stop = False
        self.index = 0
        self._shutter = threading.Thread(target=self._expose, name="sim-shutter", daemon=True)

    def wait_ready(self, timeout_s: float = 300.0) -> None:
        """Wait until the renderer process has built the scene and warmed its kernel (a first run
        compiles it: seconds, more on a loaded machine)."""
        if not self._frm_rx.poll(timeout_s):
            raise RuntimeError(f"the simulated cameras' renderer did not start within {timeout_s:.0f} s")
        self._frm_rx.recv()

    def start(self, t0: float) -> None:
        """Start exposing (after `wait_ready`); scene time is monotonic time minus t0."""
        self.t0 = t0
        self._shutter.start()

    def _expose(self) -> None:
        t_next = time.monotonic()
        while True:
            with self._cond:
                while not self._stop and (self._in_flight or time.monotonic() < t_next):
                    self._cond.wait(max(0.0, min(0.05, t_next - time.monotonic())) or 0.05)
                if self._stop:
                    return
                t_l = time.monotonic()
                T_l = pa10.fk(self.emulator.true_state().q) @ self.T_fl
                self._in_flight.append((self.index, t_l))
                self.index += 1
            self._req_tx.send((T_l, t_l - self.t0, T_l, t_l + self.skew - self.t0))
            t_next = max(t_next + self.period, time.monotonic() - self.period)

    def read(self, timeout_s: float = 1.0) -> tuple[int, np.ndarray, np.ndarray, float, float] | None:
        """The next pair (index, left, right, t_left, t_right), or None after timeout_s."""
        if not self._frm_rx.poll(timeout_s):
            return None
        left, right = self._frm_rx.recv()
        with self._cond:
            k, t_l = self._in_flight.popleft()
            self._cond.notify_all()
        return k, left, right, t_l, t_l + self.skew

    def close(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._shutter.is_alive():
            self._shutter.join(timeout=2.0)
        try:
            self._req_tx.send(None)
        except (OSError, ValueError):
            pass
        self._proc.join(timeout=5.0)
        if self._proc.is_alive():  # it ignores SIGTERM (ignore_stop_signals)
            self._proc.kill()


class ReaderCameras:
    """Real cameras for `run_realtime`: the newest pair of a `vision.sources.LatestFrameReader`."""

    def __init__(self, reader, timeout_s: float = 0.5) -> None:
        self.reader, self.timeout_s = reader, timeout_s

    def read(self) -> tuple[int, np.ndarray, np.ndarray, float, float] | None:
        f = self.reader.latest(timeout_s=self.timeout_s)
        return None if f is None else (f.index, f.left, f.right, f.t_left, f.t_right)


@dataclass(frozen=True)
class ControlJob:
    """What the control process needs, picklable (it starts with `spawn`)."""

    cfg: Config
    port: str
    T_flange_left: np.ndarray
    centre: np.ndarray
    collect: bool
    no_motion: bool
    motion_truth: TargetMotion | None  # simulation: scores the hold against the true target
    size_truth: tuple[float, float] | None
    t0: float | None  # None: sent as ("t0", t) once the session's clock starts
    settle_s: float
    rt_priority: int | None  # None: best effort (raise_priority), N: SCHED_FIFO N or an event saying why not
    simulated: bool = False  # the bridge is the simulator's emulator (errors speak of it)


#: SCHED_FIFO priority the control process asks for when no --rt-priority is given (below the
#: simulator's bridge, sim/emulator_process.py, which it waits on)
CONTROL_RT_PRIORITY = 20


def control_process(job: ControlJob, conn, stop) -> None:
    """The control loop in its own process (issue 3's measurements: a thread next to the vision
    work cannot hold 250 Hz on 2 cores; a process with SCHED_FIFO can): owns the link, runs
    `Controller` at the control rate, takes tracks from `conn`, sends back each tick's joint state
    and decision, and ends — on `stop`, a fault or an exception — with a controlled stop and the
    servo off. Its last message is ("done", Scores, collected)."""
    from photoservo.robot.link import Link

    # Ctrl-C (and SIGTERM, SIGHUP) may reach the whole process group: the vision process handles
    # it and sets `stop`, so this loop ends in order (controlled stop, servo off)
    ignore_stop_signals()
    cfg = job.cfg
    sc = Scores()
    ctrl = Controller(cfg.servo, Motion(cfg.motion, pa10.load_limits()), job.T_flange_left, job.centre,
                      collect=job.collect)
    n_events = 0
    try:
        if job.rt_priority is not None:
            try:
                set_realtime(job.rt_priority)
            except OSError as e:  # not a fault: the loop runs, only less steadily (events say so)
                ctrl.events.append((time.monotonic(), f"real-time priority {job.rt_priority} refused "
                                                      f"({e.strerror}); control runs without it"))
        else:  # a busy machine must not starve the arm's loop: the best the system permits
            ctrl.events.append((time.monotonic(), f"control process scheduling: {raise_priority(CONTROL_RT_PRIORITY)}"))
        with Link(job.port, cfg.link, simulated=job.simulated) as link:
            link.wait_state()
            if not job.no_motion:
                link.enable()
            conn.send(("ready",))
            rate = Rate(cfg.motion.rate_hz)
            track, tool, t0 = None, False, job.t0
            try:
                while not stop.is_set():
                    now = time.monotonic()
                    while conn.poll():
                        msg = conn.recv()
                        if isinstance(msg, tuple):  # ("t0", t): the session's clock started
                            t0 = msg[1]
                        else:
                            track = msg
                    st = link.state()
                    info = ctrl.step(now, st.q, st.dq, track)
                    if not job.no_motion:
                        link.send_setpoint(info.setpoint.q, info.setpoint.dq, now)
                        if info.tool != tool:
                            link.tool(info.tool)
                            tool = info.tool
                    if job.motion_truth is not None and t0 is not None:
                        _score_hold_truth(sc, ctrl, job.motion_truth, job.size_truth, info, now - t0,
                                          job.settle_s, job.centre)
                    conn.send(("tick", now, st.t, st.q, info.setpoint.q, info.setpoint.dq, info.T_base_cam_des,
                               info.phase, info.position_error_mm, info.yaw_error_deg, info.stop_reason,
                               ctrl.events[n_events:], link.quality()))
                    n_events = len(ctrl.events)
                    sc.time("control_ms", 1e3 * (time.monotonic() - now))
                    sc.time("control_late", 1e3 * rate.sleep())
            finally:
                if not job.no_motion:
                    _controlled_stop(link, sc)
    except Exception as e:  # noqa: BLE001 - a fault while moving: the arm is stopped, then reported
        sc.faults.append(f"{type(e).__name__}: {e}")
    finally:
        sc.collected = ctrl.collected
        try:
            conn.send(("done", sc))
        except (OSError, ValueError):
            pass


def run_realtime(cfg: Config, duration_s: float, *, port: str, cameras, model, rig: Rig,
                 collect: bool = False, no_motion: bool = False, recorder=None,
                 status: StatusFn | None = None, seed: int = 0, scene: SimScene | None = None,
                 t0: float | None = None, settle_s: float = 5.0, rt_priority: int | None = None,
                 stop_event: threading.Event | None = None, simulated: bool = False,
                 start_clock: Callable[[], float] | None = None, say: Callable[[str], None] | None = None) -> Scores:
    """The real-time session. The control loop (`control_process`) runs in its own process,
    connected to the bridge at `port`; this process reads stereo frames from `cameras` (`read()`
    -> (index, left, right, t_left, t_right) on the monotonic clock), places each at the joint
    state of its capture time (streamed back by the control process), runs the tracker and sends
    each track over. Stopping (duration, Ctrl-C, an error here or a fault there) ends with the
    arm stopped and the servo off. `scene` (simulation) scores hold accuracy against the truth.
    The kernels are warmed first (`warm_start`; `say` gets its notice on a first run) and the
    session's clock starts once the control process is ready: at t0, or at what `start_clock()`
    returns then (the simulator starts its cameras and world there), else when it is ready."""
    T_fl = rig.T_flange_left()
    warm_start(model, rig, cfg.fitness, say=say)  # before the arm is enabled (no-op when warmed already)
    tracker = Tracker.from_config(model, rig, cfg, seed=seed)
    sc = Scores()
    stop = stop_event or threading.Event()
    ctx = multiprocessing.get_context("spawn")
    parent, child = ctx.Pipe()
    child_stop = ctx.Event()
    job = ControlJob(cfg, port, T_fl, left_centre(rig), collect, no_motion,
                     None if scene is None else scene.motion, None if scene is None else scene.size_mm(),
                     t0, settle_s, rt_priority, simulated)
    proc = ctx.Process(target=control_process, args=(job, child, child_stop), name="photoservo-control", daemon=True)
    start_child(proc)
    history = JointHistory(keep_s=2.0, ahead_s=0.01)  # joint states streamed back by the control process
    latest: dict = {}
    result: dict = {}
    pending: list = []  # the control process's events from before the session's clock (t0) starts

    def receive() -> None:
        """Drain the control process's messages: joint states, decisions, events, the result."""
        i = 0
        while True:
            try:
                msg = parent.recv()
            except (EOFError, OSError):
                return
            if msg[0] == "tick":
                _, now, t_state, q, sp_q, sp_dq, T_des, phase, err, yaw, stop_reason, events, quality = msg
                history.append(t_state, q)
                latest.update(t=now, phase=phase, err=err, yaw=yaw, stop=stop_reason, link=quality)
                if recorder is not None and t0 is None:  # "ready" came, the clock is about to start
                    pending.extend(events)
                elif recorder is not None:
                    for t_e, text in [*pending, *events]:  # the controller's clock is monotonic
                        recorder.event(max(t_e - t0, 0.0), text)
                    pending.clear()
                    if i % 5 == 0:
                        recorder.log_arm(now - t0, q, sp_q, sp_dq)
                        if T_des is not None:
                            recorder.log_desired(now - t0, T_des)
                i += 1
            elif msg[0] == "ready":
                latest["ready"] = True
            elif msg[0] == "done":
                result["scores"] = msg[1]
                stop.set()
                return

    rx = threading.Thread(target=receive, name="control-rx", daemon=True)
    rx.start()
    prev = None
    try:
        deadline = time.monotonic() + 30.0
        while "ready" not in latest and not stop.is_set():  # the process imports, opens the link
            if time.monotonic() > deadline:
                raise RuntimeError("the control process did not start within 30 s")
            time.sleep(0.01)
        if t0 is None:  # the clock starts now: the arm is enabled, the kernels are warm
            t0 = start_clock() if start_clock is not None else time.monotonic()
            parent.send(("t0", t0))
        while not stop.is_set() and time.monotonic() - t0 < duration_s:
            c0 = time.perf_counter()
            got = cameras.read()
            if got is None:
                continue
            k, left, right, t_l, t_r = got
            sc.time("capture", 1e3 * (time.perf_counter() - c0))
            try:
                T_l = pa10.fk(history.at(t_l)[0]) @ T_fl
            except LookupError as e:  # no arm state for the capture time: cannot place the frame
                sc.dropped_frames += 1
                if recorder is not None and sc.dropped_frames == 1:
                    recorder.event(time.monotonic() - t0, f"frame dropped: {e}")
                continue
            fr = Frame(k, t_l - t0, t_r - t0, time.monotonic() - t0, left, right, T_l)
            track = _vision_step(fr, tracker, cfg, sc, recorder, scene)
            parent.send(_shift_time(track, t0))
            if track.status != prev:
                sc.lost_events += track.status == "lost"
                if recorder is not None:
                    recorder.event(fr.t_left, f"track {track.status}")
                prev = track.status
            sc.time("frame", 1e3 * (time.perf_counter() - c0))
            if status is not None and "phase" in latest:
                status({"t": time.monotonic() - t0, "frames": sc.frames, "found": track.found,
                        "status": track.status, "fitness": track.fitness,
                        "position_mm": None if track.T_base_model is None else track.T_base_model[:3, 3],
                        "alpha": track.alpha, "error_mm": latest["err"], "yaw_deg": latest["yaw"],
                        "phase": latest["phase"], "stop": latest["stop"], "link": latest["link"],
                        "fps": 1e3 / float(np.median(sc.timings_ms["frame"][-30:]))})
    finally:
        child_stop.set()
        rx.join(timeout=10.0)
        proc.join(timeout=5.0)
        if proc.is_alive():  # it ignores SIGTERM (ignore_stop_signals)
            proc.kill()
        ctl = result.get("scores")
        if ctl is None:
            sc.faults.append("the control process ended without a report (the bridge watchdog stops the arm)")
        else:
            sc.faults += ctl.faults
            sc.collected = ctl.collected
            sc.err_sq, sc.yaw_sq, sc.max_err_mm = ctl.err_sq, ctl.yaw_sq, ctl.max_err_mm
            sc.timings_ms.update({k: v for k, v in ctl.timings_ms.items()})
        sc.acquisitions = tracker.acquisitions
    return sc


def run_sim_realtime(cfg: Config, duration_s: float, sim: SimSetup, emulator, **kwargs) -> Scores:
    """`run_realtime` on the simulator: cameras rendering the scene from where `emulator` (a
    started sim.emulator.Emulator, or EmulatorProcess as `track` runs it) has the arm, the
    control process on its pty, hold scored against the truth. kwargs go to `run_realtime`."""
    cfg = sim_config(cfg)
    cams = SimCameras(cfg, emulator, sim.rig.T_flange_left())
    try:  # the kernels compile (first run) or load here and in the renderer process at once
        warm_start(sim.scene.model, sim.rig, cfg.fitness, scene=sim.scene, render_here=False, say=kwargs.get("say"))
        cams.wait_ready()

        def start_clock() -> float:  # the control process is ready: the world starts moving now
            t0 = time.monotonic()
            cams.start(t0)
            return t0
        return run_realtime(cfg, duration_s, port=emulator.path, cameras=cams, model=sim.scene.model,
                            rig=sim.rig, scene=sim.scene, simulated=True, start_clock=start_clock, **kwargs)
    finally:
        cams.close()


def _shift_time(track: Track, t0: float) -> Track:
    """The tracker ran on session time (s since t0); the control thread reads monotonic time."""
    return dataclasses.replace(track, t=track.t + t0)


def _controlled_stop(arm, sc: Scores) -> None:
    """Stop the arm in a controlled way and switch the servo off; a link that is already gone
    leaves the bridge's own watchdog to stop it (noted as a fault)."""
    try:
        arm.stop()
        arm.wait_until_still(timeout=3.0)
        arm.disable()
    except Exception as e:  # noqa: BLE001
        sc.faults.append(f"controlled stop via the link failed ({e}); the bridge watchdog stops the arm")
