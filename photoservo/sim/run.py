"""The product loop on the simulator (`photoservo track --sim`): the simulated rig, scene and arm
start (`build_sim`), and the two ways to run the loop's body (servo/session.py) on them:

  * `run_lockstep`: the simulation's own clock. Control ticks at the control rate, camera frames
    at the camera rate, each frame's track usable when it is delivered (capture + latency); the
    arm is the emulator's bridge clocked by the simulation (sim/arm.LockstepArm). Deterministic.
  * `run_sim_realtime`: time.monotonic. The session's real-time run (`run_realtime`) with the
    emulator on a pty and the simulated cameras (sim/cameras.py) rendering from where the
    emulated arm really is.

Both score the hold against the true target (servo/scores.py).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from photoservo.config import Config
from photoservo.geometry import axis_rotation, make_pose
from photoservo.robot import pa10
from photoservo.robot import protocol as P
from photoservo.servo.control import desired_camera_pose
from photoservo.servo.controller import left_centre
from photoservo.servo.scores import Scores, Truth
from photoservo.servo.warm import warm_start
from photoservo.servo.realtime import run_realtime
from photoservo.servo.session import ControlLoop, Frame, Status, StatusFn, controller_for, control_tick, \
    log_tick, vision_step
from photoservo.sim.arm import LockstepArm
from photoservo.sim.cameras import SimCameras, SimCamerasConfig
from photoservo.sim.scenes import synthetic_rig
from photoservo.sim.world import SimScene, in_view, occluded, sim_hand_eye
from photoservo.vision.rig import Rig
from photoservo.vision.track import Track
from photoservo.vision.tracker import Tracker


@dataclass
class SimSetup:
    """Everything the simulated session starts from."""

    rig: Rig
    scene: SimScene
    limits: pa10.PA10Limits
    q0: np.ndarray  # arm start: start_offset_mm and start_yaw_deg off the desired pose

    @property
    def truth(self) -> Truth:
        sc = self.scene
        return Truth(sc.motion, sc.size_mm(), sc.distractor_motion,
                     in_view=functools.partial(in_view, sc.motion, sc.model, sc.rig, sc.p.alpha_px_per_mm),
                     hidden=functools.partial(occluded, sc.p.occlusion_s))


def sim_config(cfg: Config) -> Config:
    """The simulator's config: its water plane is known, so the tracker's plausibility gates use
    it ([tracker] water_z_mm = [sim] water_z_mm unless set)."""
    if math.isfinite(cfg.tracker.water_z_mm):
        return cfg
    return dataclasses.replace(cfg, tracker=dataclasses.replace(cfg.tracker, water_z_mm=cfg.sim.water_z_mm))


def sim_rig() -> Rig:
    """The simulated rig: synthetic_rig with the simulator's hand-eye."""
    base = synthetic_rig()
    return Rig(base.left, base.right, base.R, base.T, hand_eye=sim_hand_eye(base))


def build_scene(cfg: Config) -> SimScene:
    """The simulated scene of `cfg` (deterministic: the renderer process builds its own)."""
    return SimScene(cfg.sim, cfg.photo_model, sim_rig())


def build_sim(cfg: Config) -> SimSetup:
    """The simulated rig, scene and arm start."""
    rig = sim_rig()
    scene = SimScene(cfg.sim, cfg.photo_model, rig)
    limits = pa10.load_limits()
    centre = left_centre(rig)
    T_des = desired_camera_pose(scene.motion.pose(0.0), scene.size_mm(), cfg.servo.hover_mm,
                                np.diag([-1.0, 1.0, -1.0]), centre)
    c_des = T_des[:3, :3] @ centre + T_des[:3, 3]  # rig centre over the target
    R0 = axis_rotation(2, math.radians(cfg.sim.start_yaw_deg)) @ T_des[:3, :3]
    c0 = c_des + np.array([-cfg.sim.start_offset_mm, 0.0, 0.0])
    T_cam0 = make_pose(R0, c0 - R0 @ centre)
    q0 = pa10.ik(T_cam0 @ np.linalg.inv(rig.T_flange_left()), pa10.HOME_Q, limits)
    return SimSetup(rig, scene, limits, q0)


def _capture(sim: SimSetup, arm: LockstepArm, cfg: Config, k: int, now: float, sc: Scores) -> Frame:
    """Frame k exposed at k / camera_fps (left) and lr_skew_s later (right), from where the
    lockstep arm was then; delivered capture_latency_s after the left exposure."""
    T_fl = sim.rig.T_flange_left()
    t_l = k * (1.0 / cfg.sim.camera_fps)
    t_r = t_l + cfg.sim.lr_skew_s
    T_l = pa10.fk(arm.state_at(t_l).q) @ T_fl
    T_r = pa10.fk(arm.state_at(min(t_r, now)).q) @ T_fl
    c0 = time.perf_counter()
    left, right = sim.scene.render(T_l, t_l, T_r, t_r)
    sc.time("render", 1e3 * (time.perf_counter() - c0))
    return Frame(k, t_l, t_r, t_l + cfg.sim.capture_latency_s, left, right, T_l)


def run_lockstep(cfg: Config, duration_s: float, *, collect: bool = False, no_motion: bool = False,
                 recorder=None, status: StatusFn | None = None, seed: int = 0,
                 setup: SimSetup | None = None,
                 say: Callable[[str], None] | None = None) -> Scores:
    """A simulated session on the simulator's clock (deterministic). Returns the scores; the hold
    is scored against the TRUE target from [servo] settle_s on. `say` gets the warm start's one-line
    notice of a first run."""
    cfg = sim_config(cfg)
    sim = setup or build_sim(cfg)
    ctrl = controller_for(cfg, sim.rig, collect)  # its config checked before the arm is enabled
    warm_start(sim.scene.model, sim.rig, cfg.fitness, scene=sim.scene, say=say)
    arm = LockstepArm(cfg.emulator, sim.limits, sim.q0)
    if not no_motion:
        arm.enable()
    sc = Scores(settle_s=cfg.servo.settle_s)
    c = ControlLoop(ctrl, None if no_motion else arm, sc, sim.truth)
    tracker = Tracker.from_config(sim.scene.model, sim.rig, cfg, seed=seed, time_budget=False)
    dt = 1.0 / cfg.motion.rate_hz
    k = 0
    in_flight: list[Frame] = []
    track: Track | None = None
    for i in range(int(round(duration_s / dt))):
        now = i * dt
        while k * (1.0 / cfg.sim.camera_fps) <= now + 1e-9:
            in_flight.append(_capture(sim, arm, cfg, k, now, sc))
            k += 1
        while in_flight and in_flight[0].t_delivery <= now + 1e-9:
            track = vision_step(in_flight.pop(0), tracker, cfg, sc, recorder, sim.truth, c.ctrl.events)
            sc.note_delivery(now, track.status)
        st = arm.state()
        c0 = time.perf_counter()
        tick = control_tick(c, now, st.t, st.q, st.dq, track)
        sc.time("control", 1e3 * (time.perf_counter() - c0))
        if recorder is not None:
            log_tick(recorder, tick, i)
        if status is not None and i % int(round(0.5 / dt)) == 0:
            status(Status.of(now, sc, track, tick))
        arm.tick(now + dt)
    sc.collected = c.ctrl.collected
    sc.acquisitions = tracker.acquisitions
    sc.faults += [f"bridge refused setpoint: {P.Error(n.error).name}" for n in arm.nacks]
    return sc


def run_sim_realtime(cfg: Config, duration_s: float, sim: SimSetup, emulator, **kwargs) -> Scores:
    """`run_realtime` on the simulator: cameras rendering the scene from where `emulator` (a
    started sim.emulator.Emulator, or EmulatorProcess as `track` runs it) has the arm, the
    control process on its pty, the hold scored against the truth. kwargs go to `run_realtime`."""
    cfg = sim_config(cfg)
    cv_threads = cv2.getNumThreads()
    cv2.setNumThreads(1)  # the renderer, control and emulator processes share the cores: no spinning OpenCV pool
    cams = SimCameras(SimCamerasConfig(cfg.sim.camera_fps, cfg.sim.lr_skew_s), functools.partial(build_scene, cfg),
                      emulator, sim.rig.T_flange_left(), (sim.rig.left.size, sim.rig.right.size))
    cams.connect()
    try:  # the kernels compile (first run) or load here and in the renderer process at once
        warm_start(sim.scene.model, sim.rig, cfg.fitness, scene=sim.scene, render_here=False, say=kwargs.get("say"))
        cams.wait_ready()

        def start_clock() -> float:  # the control process is ready: the world starts moving now
            t0 = time.monotonic()
            cams.start(t0)
            return t0
        return run_realtime(cfg, duration_s, port=emulator.path, read_frame=cams.read, model=sim.scene.model,
                            rig=sim.rig, truth=sim.truth, simulated=True, start_clock=start_clock,
                            keep_ids=emulator.ids, **kwargs)
    finally:
        cams.disconnect()
        cv2.setNumThreads(cv_threads)
