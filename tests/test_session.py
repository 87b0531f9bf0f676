"""The tracking session (issue 5): controller safety, the lockstep arm behind the wire protocol,
and the closed-loop acceptance runs on the simulator's clock."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from photoservo.robot import pa10
from photoservo.robot import protocol as P
from photoservo.cli.main import main
from photoservo.config import load_config
from photoservo.servo.motion import Motion
from photoservo.servo.controller import Controller, left_centre
from photoservo.sim.arm import LockstepArm
from photoservo.sim.run import build_sim, run_lockstep
from photoservo.sim.world import TargetMotion, sim_hand_eye
from photoservo.sim.scenes import synthetic_rig
from photoservo.vision.track import Track

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _track(t, T, v=(0.0, 0.0, 0.0)):
    return Track(t=t, status="tracking", found=True, fitness=0.9, T_base_model=T,
                 velocity_mm_s=np.asarray(v, float), alpha=2.0, size_mm=(130.0, 42.0), R_left=None,
                 t_left=None, alpha_measured=2.0, generations=8, seconds=0.01)


@pytest.fixture(scope="module")
def cfg():
    return load_config()


def _controller(cfg, collect=False):
    rig = synthetic_rig()
    R, t = sim_hand_eye(rig)
    T_fl = np.eye(4)
    T_fl[:3, :3], T_fl[:3, 3] = R, t
    return Controller(cfg.servo, Motion(cfg.motion, pa10.load_limits()), T_fl, left_centre(rig), collect=collect)


def test_controller_stops_without_target_or_with_stale_estimate(cfg):
    ctrl = _controller(cfg)
    q, dq = pa10.HOME_Q.copy(), np.full(7, 0.05)
    info = ctrl.step(0.0, q, dq, None)
    assert info.stop_reason == "no target" and info.T_base_cam_des is None
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = [700.0, 0.0, -100.0]
    info = ctrl.step(1.0, q, dq, _track(1.0 - 2 * cfg.servo.max_estimate_age_s, T))
    assert "old" in info.stop_reason
    # a stop decelerates: the commanded speed is below the measured one
    assert np.linalg.norm(info.setpoint.dq) < np.linalg.norm(dq)
    info = ctrl.step(1.0, q, np.zeros(7), _track(1.0, T))
    assert info.stop_reason == "" and info.T_base_cam_des is not None
    _pace(ctrl, q, T, 1.9, fps=30.0, latency_s=0.05)  # frames at 30 fps: the limit is max_estimate_age_s
    # a fresh frame whose pose is coasting on a measurement older than max_estimate_age_s
    coasting = dataclasses.replace(_track(2.0, T), status="coasting", found=False,
                                   coast_s=1.5 * cfg.servo.max_estimate_age_s)
    assert "old" in ctrl.step(2.0, q, np.zeros(7), coasting).stop_reason


def _pace(ctrl, q, T, t_end, fps, latency_s, n=12):
    """Steps the controller with n fresh tracks at `fps`, each delivered latency_s after its
    capture, the last captured at t_end - latency_s; returns the last step's info."""
    for k in range(n - 1, -1, -1):
        t = t_end - latency_s - k / fps
        info = ctrl.step(t + latency_s, q, np.zeros(7), _track(t, T))
    return info


def test_estimate_age_limit_follows_the_measured_frame_interval(cfg):
    """At 3 fps an estimate is 0.33 s older before the next frame comes: the arm must not
    stop-start on every frame (max_estimate_age_s = 0.3 alone did); at 30 fps the same age
    stops it, and a coasting pose at 3 fps stops once it is older than the latency and two
    frame intervals (issue 10). Before: stopped at 3 fps too."""
    q, T = pa10.HOME_Q.copy(), np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = [700.0, 0.0, -100.0]
    slow, fast = _controller(cfg), _controller(cfg)
    _pace(slow, q, T, 5.0, fps=3.0, latency_s=0.15)
    _pace(fast, q, T, 5.0, fps=30.0, latency_s=0.15)
    t_frame = 5.0 - 0.15  # the newest track's capture time
    late = 5.0 + 0.3  # just before the next frame at 3 fps: 0.45 s old
    assert slow.step(late, q, np.zeros(7), _track(t_frame, T)).stop_reason == ""
    assert "old" in fast.step(late, q, np.zeros(7), _track(t_frame, T)).stop_reason
    coasting = dataclasses.replace(_track(t_frame, T), status="coasting", found=False, coast_s=0.7)
    assert "old" in slow.step(late, q, np.zeros(7), coasting).stop_reason  # 1.15 s > 0.15 + 2 / 3
    assert slow.pace.interval_s == pytest.approx(1 / 3) and slow.pace.latency_s == pytest.approx(0.15)


def test_controller_refuses_target_out_of_reach(cfg):
    ctrl = _controller(cfg)
    T = np.eye(4)
    T[:3, 3] = [2500.0, 0.0, -100.0]
    info = ctrl.step(0.0, pa10.HOME_Q, np.zeros(7), _track(0.0, T))
    assert info.stop_reason == "target out of reach"


def test_target_motion_is_face_up_drifting_and_heaving():
    cfg = load_config()
    m = TargetMotion.from_params(cfg.sim)
    T0, T1 = m.pose(0.0), m.pose(1.0)
    assert T0[2, 2] < -0.99  # model z points down into the water at rest (no roll/pitch at t=0 up to pitch phase)
    d = T1[:3, 3] - T0[:3, 3]
    assert d[:2] == pytest.approx(cfg.sim.drift_mm_s, abs=1e-9)
    zs = [m.pose(t)[2, 3] - cfg.sim.water_z_mm for t in np.linspace(0, 4, 81)]
    assert max(zs) == pytest.approx(cfg.sim.heave_mm, rel=0.01) and min(zs) == pytest.approx(-cfg.sim.heave_mm, rel=0.01)
    h = (m.pose(0.3)[:3, 3] - m.pose(0.29)[:3, 3]) / 0.01
    assert h == pytest.approx(m.velocity(0.295), abs=0.5)


def test_irregular_sea_is_no_one_sinusoid_with_the_same_rms_and_a_consistent_velocity():
    """`[sim] heave_irregular`: the check of the tracker's heave model on a sea it was not made
    for; seeded, about the regular heave's RMS, not periodic at heave_period_s."""
    cfg = load_config(overrides=["sim.heave_irregular=true"])
    m = TargetMotion.from_params(cfg.sim)
    assert m.heave_terms == TargetMotion.from_params(cfg.sim).heave_terms and len(m.heave_terms) == 5
    t = np.arange(0.0, 120.0, 0.05)
    z = np.array([m.pose(x)[2, 3] for x in t]) - cfg.sim.water_z_mm
    assert np.sqrt(np.mean(z ** 2)) == pytest.approx(cfg.sim.heave_mm / np.sqrt(2), rel=0.15)
    period = int(round(cfg.sim.heave_period_s / 0.05))
    assert np.sqrt(np.mean((z[period:] - z[:-period]) ** 2)) > 5.0  # one sinusoid would repeat exactly
    h = (m.pose(7.31)[:3, 3] - m.pose(7.30)[:3, 3]) / 0.01
    assert h == pytest.approx(m.velocity(7.305), abs=0.5)


def test_lockstep_arm_speaks_the_wire_protocol(cfg):
    arm = LockstepArm(cfg.emulator, pa10.load_limits(), pa10.HOME_Q)
    q = pa10.HOME_Q.copy()
    arm.send_setpoint(q + 0.001, np.zeros(7), 0.0)  # before enable: refused by the bridge
    assert arm.nacks and arm.nacks[-1].error == P.Error.SERVO_OFF
    arm.enable()
    dt = 1.0 / cfg.emulator.control_hz
    target = q.copy()
    for i in range(50):
        target[0] += 0.1 * dt  # 0.1 rad/s on S1
        arm.send_setpoint(target, np.r_[0.1, np.zeros(6)], i * dt)
        arm.tick((i + 1) * dt)
    assert arm.state().q[0] == pytest.approx(target[0], abs=2e-3)
    bad = q.copy()
    bad[1] = math.radians(120)  # S2 range is +-91 deg
    n = len(arm.nacks)
    arm.send_setpoint(bad, np.zeros(7), 0.3)
    assert len(arm.nacks) == n + 1
    mid = arm.state_at(25.5 * dt)
    assert arm.state_at(25 * dt).q[0] < mid.q[0] < arm.state_at(26 * dt).q[0]


def test_track_refuses_rig_without_hand_eye(tmp_path, capsys):
    from photoservo.vision.rig import default_rig, save_rig

    save_rig(default_rig(), tmp_path / "rig.toml")
    rc = main(["track", "--rig", str(tmp_path / "rig.toml"), "--photo", str(EXAMPLES / "photos" / "squid.png"),
               "--port", "/dev/null-nope", "--no-record"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "hand_eye" in err[0]


def test_track_rejects_bad_duration(capsys):
    assert main(["track", "--sim", "--duration", "-1", "--no-record"]) == 2
    assert "--duration" in capsys.readouterr().err


# ----------------------------------------------------------------------------- acceptance (issue 5)

ACCEPTANCE = [  # the scene: drift 30 mm/s, heave +-20 mm / 4 s, roll and pitch +-5 deg / 3 s,
    "sim.drift_mm_s=[0.0, 30.0]", "sim.heave_mm=20.0", "sim.heave_period_s=4.0",  # arm 150 mm, 10 deg off
    "sim.roll_deg=5.0", "sim.roll_period_s=3.0", "sim.pitch_deg=5.0", "sim.pitch_period_s=3.0",
    "sim.start_offset_mm=150.0", "sim.start_yaw_deg=10.0",
]


def test_acceptance_hold_then_collect_on_the_simulators_clock():
    # hold_time_s = 7: the hold is reached within ~1.5 s, so the descent starts after ~8.5 s and
    # 5 s .. 8.5 s is scored while holding; the collection then takes ~5 s
    cfg = load_config(overrides=ACCEPTANCE + ["servo.hold_time_s=7.0", "servo.collect_speed_mm_s=150.0",
                                              "servo.settle_s=5.0"])
    sc = run_lockstep(cfg, 15.0, collect=True, seed=0)
    s = sc.summary()
    first = next(k for k, f in enumerate(sc.truth_frames) if f.status == "tracking")  # after the acquisition
    assert s["lost_events"] == 0 and all(f.status == "tracking" for f in sc.truth_frames[first:]), s
    assert len(sc.held()) > cfg.sim.camera_fps * 2  # at least 2 s of holding scored (frames)
    t_descend = next(t for t, text in sc.phase_events if text.startswith("phase descend"))
    assert max(h.t for h in sc.held()) < t_descend  # not while collecting
    assert s["hold_error_rms_mm"] <= 10.0, s
    assert s["hold_yaw_error_rms_deg"] <= 3.0, s
    assert s["collected"], s
    assert not s["faults"], s


def test_hold_at_8_fps_follows_the_heave_not_a_lagging_constant_velocity():
    """The real-time loop at load 0.6 runs ~8-11 fps with a few generations a frame and the
    track reaching the arm ~0.15 s after capture. The creature heaves +-20 mm every 4 s: the
    tracker fits that oscillation (vision/heave.py) and the servo law aims at the heave at the
    control period's time, so the arm holds <= 15 mm RMS against the TRUE target (issue 10).
    Before: the constant-velocity filter's height lagged the heave (height error 21 mm RMS at
    the controller, worse than not following it) and the hold was 28.8 mm RMS."""
    cfg = load_config(overrides=ACCEPTANCE + ["sim.camera_fps=8", "tracker.generations_per_frame=3",
                                              "sim.capture_latency_s=0.15", "servo.settle_s=5.0"])
    sc = run_lockstep(cfg, 12.0, seed=0)
    s = sc.summary()
    assert s["found_ratio"] >= 0.9 and s["false_tracks"] == 0, s
    assert s["hold_error_rms_mm"] <= 15.0, s
    assert s["track_error_mm"]["median"] <= 8.0, s


def test_distractor_in_view_never_draws_the_arm():
    cfg = load_config(overrides=ACCEPTANCE + ["sim.distractor=true", "servo.settle_s=3.0"])
    sc = run_lockstep(cfg, 6.0, seed=0)
    s = sc.summary()
    assert s["lost_events"] == 0, s
    # the rig centre stays over the target, never over the look-alike 260 mm away
    assert s["distractor_min_mm"] > 150.0, s
    assert s["hold_error_rms_mm"] <= 15.0, s


def test_realtime_session_over_a_real_pty_stops_and_disables_the_arm():
    """The control loop in its own process over the emulator's pty; the session ends with the arm
    at rest and the servo off, and the control process ran at its rate."""
    from photoservo.sim.emulator_process import EmulatorProcess
    from photoservo.robot.link import Link
    from photoservo.sim.run import run_sim_realtime

    # the shared test machine can stall a process for a few hundred ms: allow the link 1 s of
    # silence (default 0.25 s) so that the test checks the session's ending, not the machine
    cfg = load_config(overrides=["sim.camera_fps=10.0", "link.silence_timeout_s=1.0"])
    sim = build_sim(cfg)
    emu = EmulatorProcess(cfg.emulator, sim.limits, q0=sim.q0)  # as `track --sim` runs it
    path = emu.start()
    try:
        sc = run_sim_realtime(cfg, 5.0, sim, emu)
        assert sc.frames >= 2 and not sc.faults, sc.summary()
        assert len(sc.timings_ms["control_late"]) > 250  # the control process ran at its rate
        with Link(path, cfg.link) as link:
            st = link.wait_state()  # a report sent after the session ended
        assert not st.servo_on and not st.moving  # controlled stop, then servo off
        assert not emu.true_state().status & P.Status.SERVO_ON  # the published true state agrees
    finally:
        emu.stop()
    assert emu.summary["accepted"] > 100  # setpoints reached the bridge and were carried out
    assert emu.error == ""


def test_ctrl_c_stops_the_arm_and_leaves_a_verified_recording(tmp_path):
    """SIGINT to a running `photoservo track --sim` (real time, control process on the emulator's
    pty): exit 130, one line on stderr and no traceback, a recording that `rerun rrd verify`
    accepts and whose event log shows the session ran."""
    import signal
    import subprocess
    import sys
    import time

    from photoservo.record.files import verify_rrd
    from photoservo.record.reader import read_recording

    rec = tmp_path / "ctrl_c.rrd"
    proc = subprocess.Popen([sys.executable, "-m", "photoservo.cli", "track", "--sim", "--duration", "60",
                             "--record", str(rec), "--set", "sim.camera_fps=10.0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 90
        seen = ""
        while "tracking" not in seen:  # the status line (a line per second without a terminal)
            line = proc.stderr.readline()
            assert line and time.monotonic() < deadline, f"track ended or stalled: {seen[-500:]}"
            seen += line
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "interrupted" in err
    ok, msg = verify_rrd(rec)
    assert ok, msg
    r = read_recording(rec)
    assert len(r.frames) >= 1 and any("track tracking" in text for _, _, text in r.events)



def _emulator_pid(parent: int) -> int | None:
    """The child process of `parent` that runs the bridge emulator: the one holding the pty's
    master side (/dev/ptmx). (Python 3.11 does not give threads OS names to look for.)"""
    import os

    for tid in os.listdir(f"/proc/{parent}/task"):
        for child in open(f"/proc/{parent}/task/{tid}/children").read().split():
            try:
                fds = [os.readlink(f"/proc/{child}/fd/{fd}") for fd in os.listdir(f"/proc/{child}/fd")]
            except OSError:
                continue
            if "/dev/ptmx" in fds:
                return int(child)
    return None


def test_a_link_fault_ends_the_session_with_exit_3_and_an_error_event_in_the_recording(tmp_path):
    """The simulator's bridge hangs mid-session (its process stopped for 1 s): the link reports
    it silent, `track --sim` exits 3 with the fault on stdout and no traceback, and the
    recording's event log holds the fault at level ERROR (an INFO line among the control events
    before, if at all)."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from photoservo.record.reader import read_recording

    rec = tmp_path / "hang.rrd"
    proc = subprocess.Popen([sys.executable, "-m", "photoservo.cli", "track", "--sim", "--duration", "60",
                             "--record", str(rec), "--set", "sim.camera_fps=10.0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stderr.readline()  # the first status line: frames are being recorded
        assert " fps " in line, line
        emu = _emulator_pid(proc.pid)
        assert emu is not None or proc.poll() is not None  # (a very busy machine: silent by itself)
        if emu is not None:
            os.kill(emu, signal.SIGSTOP)
            time.sleep(1.0)
            os.kill(emu, signal.SIGCONT)
        out, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == 3 and "Traceback" not in err, err[-2000:]
    assert "fault: LinkError" in out and "silent" in out, out
    errors = [text for _, level, text in read_recording(rec).events if level == "ERROR"]
    assert any(text.startswith("fault: LinkError") and "silent" in text for text in errors), errors


def test_a_link_fault_as_the_control_process_starts_is_exit_3_not_a_traceback():
    """A line so noisy (5 % of the bytes corrupted) that the bridge never answers HELLO: the
    control process ends before the session's clock starts. The vision process's message to it
    met a closed pipe and the run ended in a traceback; now exit 3 with the fault."""
    import subprocess
    import sys

    p = subprocess.run([sys.executable, "-m", "photoservo.cli", "track", "--sim", "--duration", "4", "--no-record",
                        "--set", "sim.camera_fps=5.0", "--set", "emulator.corrupt=0.05"],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 3 and "Traceback" not in p.stderr, p.stderr[-2000:]
    assert "fault: Link" in p.stdout and "HELLO" in p.stdout, p.stdout  # LinkError or LinkQualityError


#: a search pose for the simulator's scene (joints, deg): the rig 800 mm over the water at
#: (700, 200) mm, ahead of the creature's drift, looking straight down (pa10.ik of that pose)
SIM_SEARCH_POSE_DEG = [14.8, 37.4, 3.4, 28.2, -2.3, 114.5, 16.6]


def _gone(t, status="out_of_view"):
    return Track(t=t, status=status, found=False, fitness=0.2, T_base_model=None, velocity_mm_s=np.zeros(3),
                 alpha=2.0, size_mm=(130.0, 42.0), R_left=None, t_left=None, alpha_measured=None,
                 generations=8, seconds=0.01)


def test_controller_moves_to_the_search_pose_out_of_view_and_servos_again_once_found(cfg):
    """[servo] search_pose_deg: lost in view, the arm holds; out of view, a jerk-limited move to
    the configured joints, carried on whatever the tracker says meanwhile (lost, acquiring) and
    never from an estimate; a fresh pose ends the search, an old one does not."""
    from photoservo.servo.session import controller_for
    from photoservo.sim.run import sim_rig

    c = dataclasses.replace(cfg, servo=dataclasses.replace(cfg.servo, search_pose_deg=tuple(SIM_SEARCH_POSE_DEG)))
    ctrl = controller_for(c, sim_rig())
    q, dq, t, dt = build_sim(cfg).q0, np.zeros(7), 0.0, 1.0 / cfg.motion.rate_hz
    info = ctrl.step(t, q, dq, _gone(t, "lost"))
    assert ctrl.phase == "servo" and info.stop_reason == "no target"  # lost in view: hold
    speeds = []
    for i in range(int(8.0 / dt)):
        info = ctrl.step(t, q, dq, _gone(t, ("out_of_view", "lost", "acquiring")[min(i // 100, 2)]))
        q, dq, t = info.setpoint.q, info.setpoint.dq, t + dt
        speeds.append(np.max(np.abs(dq) / pa10.load_limits().dq_max))
        if info.stop_reason == "at the search pose":
            break
    assert ctrl.phase == "search" and info.stop_reason == "at the search pose", info.stop_reason
    assert np.degrees(np.abs(q - np.radians(SIM_SEARCH_POSE_DEG))).max() < 0.1 and max(speeds) <= 1.0 + 1e-9
    assert ctrl.events[0][1].startswith("phase search")
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = [700.0, 200.0, -100.0]
    old = _track(t - 2 * cfg.servo.max_estimate_age_s, T)
    info = ctrl.step(t, q, dq, old)
    assert ctrl.phase == "search" and info.T_base_cam_des is None and info.stop_reason == "at the search pose"
    info = ctrl.step(t, q, dq, _track(t, T))
    assert ctrl.phase == "servo" and info.T_base_cam_des is not None and ctrl.events[-1][1].startswith("phase servo")


def test_search_pose_out_of_the_arms_limits_is_one_line_exit_2(capsys):
    bad = list(SIM_SEARCH_POSE_DEG)
    bad[1] = 120.0  # S2 beyond its range
    for value, says in ((bad, "servo.search_pose_deg' = [14.8, 120"), (bad[:6], "must be [] or 7 joint angles")):
        assert main(["track", "--sim", "--lockstep", "--duration", "1", "--no-record",
                     "--set", f"servo.search_pose_deg={value}"]) == 2
        err = capsys.readouterr().err
        assert says in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, err


def test_creature_leaving_the_view_sends_the_arm_to_the_search_pose_and_is_found_there():
    """The arm cannot keep up ([servo] max_speed_mm_s = 1): the creature drifts out of view, the
    arm moves to the search pose (ahead of the drift), the whole volume finds the creature
    there and servoing resumes; no false track."""
    cfg = load_config(overrides=[f"servo.search_pose_deg={SIM_SEARCH_POSE_DEG}", "servo.max_speed_mm_s=1.0",
                                 "sim.camera_fps=10", "servo.settle_s=1.0"])
    sc = run_lockstep(cfg, 6.0, seed=0)
    s = sc.summary()
    phases = [text.split(":")[0] for _, text in sc.phase_events]
    assert phases == ["phase search", "phase servo"], sc.phase_events
    t_search, t_servo = sc.phase_events[0][0], sc.phase_events[1][0]
    assert any(f.status == "out_of_view" and f.in_view < 0.6 for f in sc.truth_frames if f.t <= t_search)
    assert t_servo - t_search < 2.0 and s["final_status"] == "tracking" and s["false_tracks"] == 0, s
    assert all(f.status == "tracking" and f.in_view == 1.0 for f in sc.truth_frames if f.t > t_servo + 0.5), s
