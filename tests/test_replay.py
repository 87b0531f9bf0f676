"""Replay (issues 6, 12, 13): a recording re-run from its file alone reproduces the recorded
lockstep run, is deterministic, writes a recording that replays again, follows config changes and
recorded generation counts; a compact recording replays tracker / GA / servo changes exactly as
the full frames do and refuses hue changes; `track --world-from` rebuilds the same simulated
world; the path `track` prints opens as printed; truncated and bad files are one-line errors."""

from __future__ import annotations

import dataclasses
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from photoservo.errors import InputError
from photoservo.cli.main import main
from photoservo.config import load_config
from photoservo.record.planes import tracker_input
from photoservo.record.files import verify_rrd
from photoservo.record.recorder import Recorder
from photoservo.record.replay import load_replay, replay
from photoservo.record.reader import iter_frames, read_recording
from photoservo.tomlconf import dump_config
from photoservo.vision.fitness import StereoHue

# 6 frames; the whole-volume search in the first frame (not spread over frames: the run is short)
SHORT = ["--sim", "--lockstep", "--duration", "1.2", "--set", "sim.camera_fps=5", "--set",
         "tracker.acquire_generations=100000"]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    """A real `track --sim --lockstep` recording: 1.2 s at 5 fps (6 frames), tracker seed 3."""
    path = tmp_path_factory.mktemp("rec") / "run.rrd"
    assert main(["track", *SHORT, "--seed", "3", "--record", str(path)]) == 0
    return path


def _est(e) -> tuple:
    return (e.frame, e.found, e.fitness, e.generations,
            None if e.position_mm is None else tuple(e.position_mm))


def test_replay_reproduces_the_lockstep_run_and_is_deterministic(recorded: Path, tmp_path: Path):
    setup = load_replay(recorded)
    assert setup.seed == 3 and setup.cfg.sim.lockstep and not setup.recorded_generations
    assert "fixed 8 generations" in setup.generations_note
    r1 = replay(setup, tmp_path / "r1.rrd")
    r2 = replay(load_replay(recorded), tmp_path / "r2.rrd")
    assert len(r1.frames) == 6 and r1.frames == r2.frames          # frame for frame
    assert r1.commands.shape[0] > 10 and np.array_equal(r1.commands, r2.commands)
    # the same frames, seed and generations as the recorded run: the same estimates, bit for bit
    a, b = read_recording(recorded), read_recording(r1.out_path)
    assert [_est(e) for e in a.estimates] == [_est(e) for e in b.estimates]
    assert a.estimates[1].found
    # open-loop commands on the recorded joint states: close to what the closed loop commanded
    ca, cb = a.arm["command"].values, b.arm["command"].values
    assert ca.shape == cb.shape and np.abs(ca - cb).max() < 0.01 * max(1e-3, np.abs(ca).max())
    assert np.abs(a.arm["q"].values - b.arm["q"].values).max() < 1e-9
    for key in ("mean_fitness", "found_ratio", "jitter_mm", "track_err_mm", "size_err_mm"):
        assert r1.comparison.row(key).delta == 0.0, key
    # the replay's recording is complete (verifies) and replays itself to the same result
    assert verify_rrd(b.path)[0]
    assert b.setup.run["verb"] == "replay" and b.setup.seed == a.setup.seed and len(b.truth) == 6
    r3 = replay(load_replay(r1.out_path), tmp_path / "r3.rrd")
    assert r3.frames == r1.frames
    fa, fb = next(iter_frames(recorded)), next(iter_frames(r1.out_path))   # the same planes and video
    assert fa.planes.keys() == fb.planes.keys() and all(np.array_equal(fa.planes[k], fb.planes[k]) for k in fa.planes)
    assert [s.data for s in fa.video["left"]] == [s.data for s in fb.video["left"]]


def test_changed_ga_setting_changes_the_table(recorded: Path, tmp_path: Path, capsys):
    out = tmp_path / "ga.rrd"
    rc = main(["replay", str(recorded), "--set", "tracker.generations_per_frame=1",
               "--set", "ga.population=12", "--out", str(out), "--json"])
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    t = doc["table"]
    assert doc["frames"] == 6 and doc["fps"] > 0 and doc["replay"] == str(out)
    assert t["mean_fitness"]["replay"] != t["mean_fitness"]["recorded"]
    assert t["jitter_mm"]["replay"] != t["jitter_mm"]["recorded"]
    assert t["frames"]["replay"] == t["frames"]["recorded"] == 6
    assert t["track_err_mm"]["replay"] is not None           # truth carried over
    cfg = tomllib.loads(read_recording(out).setup.config_toml)
    assert cfg["tracker"]["generations_per_frame"] == 1 and cfg["ga"]["population"] == 12
    assert all(e.generations == 1 for e in read_recording(out).estimates[1:])
    # the text table
    assert main(["replay", str(recorded), "--set", "tracker.generations_per_frame=1",
                 "--set", "ga.population=12", "--out", str(tmp_path / "ga2.rrd")]) == 0
    text = capsys.readouterr().out
    assert "recorded" in text and "replay" in text and "mean fitness" in text and "frames/s" in text


def _relog(src: Path, dst: Path, cfg_text: str, generations: int) -> None:
    """A copy of `src` made with the Recorder: same setup and frames, another config, and the
    given generation count logged for every tracking frame (as a time-budgeted run would)."""
    a = read_recording(src)
    with Recorder.open(dst, "track") as rec:
        s = a.setup
        rec.log_static_setup(s.rig_toml, s.photo_bgr, s.model, cfg_text, s.seed)
        for fr, m, e in zip(iter_frames(src), a.frames, a.estimates):
            hue, left, right = tracker_input(fr.planes, StereoHue)
            rec.log_frame(fr.index, m.t, left, right, T_base_left=m.T_base_left,
                          capture_times=m.capture_times, fitness_input=hue, video=fr.video)
            rec.log_estimate(fr.index, m.t, found=e.found, fitness=e.fitness,
                             generations=e.generations if fr.index == 0 else generations,
                             T_base_left=m.T_base_left)
            rec.log_timings(m.t, {"hue": 10.0, "ga": 40.0}, frame=fr.index)
        for t, q in zip(a.arm["q"].t, a.arm["q"].values):
            rec.log_arm(t, q)


def test_real_time_recording_replays_with_its_recorded_generation_counts(recorded: Path, tmp_path: Path):
    cfg = load_config(recorded=("test", tomllib.loads(read_recording(recorded).setup.config_toml)))
    cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, lockstep=False))
    rt = tmp_path / "rt.rrd"
    _relog(recorded, rt, dump_config(cfg), generations=3)
    setup = load_replay(rt)
    assert setup.recorded_generations and "recorded generation counts" in setup.generations_note
    res = replay(setup, tmp_path / "a.rrd")
    assert res.frames[0].generations == 0   # the acquisition (whole here): the tracking search starts next frame
    assert [f.generations for f in res.frames[1:]] == [3] * 5
    # a real-time run's track reached the control law after the frame's hue + GA time (50 ms)
    t_first = read_recording(rt).frames[0].capture_times[0]
    t_track = next(t for t, text in res.events if text == "track tracking")
    assert t_track == pytest.approx(t_first + setup.cfg.sim.capture_latency_s + 0.05)
    fixed = replay(load_replay(rt, fixed_generations=True), tmp_path / "b.rrd")
    assert [f.generations for f in fixed.frames[1:]] == [8] * 5
    assert fixed.frames[1].fitness != res.frames[1].fitness
    # changing generations_per_frame overrides the recorded counts
    assert not load_replay(rt, overrides=["tracker.generations_per_frame=5"]).recorded_generations


def test_world_from_rebuilds_the_same_world(recorded: Path, tmp_path: Path, capsys):
    same, gains = tmp_path / "same.rrd", tmp_path / "gains.rrd"
    # no --duration, --seed, --set sim.*: all from the recording
    assert main(["track", "--sim", "--world-from", str(recorded), "--record", str(same)]) == 0
    out = capsys.readouterr().out
    assert "recorded" in out and "this run" in out and "track error" in out and "hold error" in out
    a, b = read_recording(recorded), read_recording(same)
    assert [_est(e) for e in a.estimates] == [_est(e) for e in b.estimates]   # deterministic
    assert np.array_equal(a.arm["command"].values, b.arm["command"].values)
    assert main(["track", "--sim", "--world-from", str(recorded), "--record", str(gains),
                 "--set", "servo.k_position=0.3"]) == 0
    assert "this run" in capsys.readouterr().out
    c = read_recording(gains)
    assert len(c.truth) == len(a.truth)
    for x, y in zip(a.truth, c.truth):   # the same target motion (the world) ...
        assert np.array_equal(x.T_base_target, y.T_base_target)
    assert not np.array_equal(a.arm["command"].values, c.arm["command"].values)   # ... other gains
    assert tomllib.loads(c.setup.config_toml)["servo"]["k_position"] == 0.3


def test_world_from_refuses_a_recording_without_truth(tmp_path: Path, capsys):
    p = tmp_path / "move.rrd"
    with Recorder.open(p, "move") as rec:
        rec.log_arm(0.0, np.zeros(7))
    assert main(["track", "--sim", "--world-from", str(p), "--no-record"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no ground truth" in err[0]


def _one_line_error(argv: list[str], capsys, *needles: str) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for n in needles:
        assert n in err[0], err[0]


def test_bad_recordings_are_one_line_errors(recorded: Path, tmp_path: Path, capsys):
    _one_line_error(["replay", str(tmp_path / "nope.rrd")], capsys, "nope.rrd", "not found")
    junk = tmp_path / "junk.rrd"
    junk.write_bytes(b"this is not a recording" * 100)
    _one_line_error(["replay", str(junk)], capsys, "junk.rrd")
    preview = tmp_path / "preview.rrd"
    a = read_recording(recorded)
    with pytest.warns(UserWarning, match="CANNOT be replayed"):
        rec = Recorder.open(preview, "track", mode="preview")
    with rec:
        rec.log_static_setup(a.setup.rig_toml, None, a.setup.model, a.setup.config_toml, 0)
        _, left, right = tracker_input(next(iter_frames(recorded)).planes, StereoHue)
        rec.log_frame(0, 0.0, left, right, T_base_left=a.frames[0].T_base_left)
    _one_line_error(["replay", str(preview)], capsys, "preview", "cannot be replayed")
    bare = tmp_path / "bare.rrd"
    with Recorder.open(bare, "move") as rec:
        rec.log_arm(0.0, np.zeros(7))
    _one_line_error(["replay", str(bare)], capsys, "bare.rrd", "no effective config")
    _one_line_error(["replay", str(recorded), "--set", "ga.nope=1"], capsys, "ga.nope")
    with pytest.raises(InputError, match="preview"):
        load_replay(preview)


def test_hold_error_row_against_hand_computed_numbers(tmp_path: Path):
    """The table's hold row is the hold score of servo/scores.py: frames with truth captured from
    [servo] settle_s on while the controller servoed (by the recorded phase events)."""
    from photoservo.geometry import make_pose
    from photoservo.record.compare import run_metrics
    from photoservo.servo.controller import phase_event
    from photoservo.vision.rig import Rig, default_rig, dump_rig

    base = default_rig()
    rig = Rig(base.left, base.right, np.eye(3), np.array([-100.0, 0.0, 0.0]))   # centre: x = +50 mm
    down = np.diag([1.0, -1.0, -1.0])
    path = tmp_path / "hold.rrd"
    with Recorder.open(path, "track") as rec:
        rec.log_static_setup(dump_rig(rig), None, None, "[servo]\nhover_mm = 600.0\nsettle_s = 0.05\n", 0)
        img = np.zeros((8, 8, 3), np.uint8)
        for k, truth in enumerate([(50, 30, 360), (50, 0, 400), (50, 30, 360), (50, 30, 360), None]):
            rec.log_frame(k, 0.1 * k, img, img, T_base_left=make_pose(down, [0, 0, 1000.0]),
                          capture_times=(0.1 * k, 0.1 * k + 0.001))
            if truth is not None:
                rec.log_truth(k, 0.1 * k, make_pose(down, np.array(truth, dtype=float)), (20, 10))
        rec.event(0.25, phase_event("descend", "holding"))
    # rig centre (50, 0, 1000); wanted 600 mm above the truth: (50, 0, 1000) -> 0 mm,
    # (50, 30, 960) -> |(0, -30, 40)| = 50 mm. Frame 0 is before settle_s, frame 3 after the
    # descent began, frame 4 has no truth: frames 1 and 2 count
    m = run_metrics(read_recording(path))
    assert m["hold_err_mm"] == pytest.approx(np.sqrt(2500 / 2))
    assert m["hold_yaw_err_deg"] == pytest.approx(0.0, abs=1e-9)   # camera x along the target's long axis


def test_replay_table_and_track_json_agree_on_the_same_run(tmp_path: Path, capsys):
    """Issue 14: one definition of each score. The hold error and hold yaw error `track --json`
    prints are the numbers replay's table computes from the run's recording, and so are the
    frames and the found ratio; the replay (same frames, truth copied) gives them again."""
    path = tmp_path / "run.rrd"
    assert main(["track", "--sim", "--lockstep", "--duration", "3", "--set", "sim.camera_fps=5", "--seed", "3",
                 "--set", "servo.settle_s=1.0", "--record", str(path), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert main(["replay", str(path), "--no-record", "--json"]) == 0
    t = json.loads(capsys.readouterr().out)["table"]
    assert s["frames"] == t["frames"]["recorded"] == t["frames"]["replay"] == 15
    assert s["found_ratio"] == t["found_ratio"]["recorded"] == t["found_ratio"]["replay"]
    assert s["hold_error_rms_mm"] > 0.0
    for live, row in (("hold_error_rms_mm", "hold_err_mm"), ("hold_yaw_error_rms_deg", "hold_yaw_err_deg")):
        assert t[row]["recorded"] == pytest.approx(s[live], rel=1e-12, abs=1e-12), row
        assert t[row]["replay"] == pytest.approx(s[live], rel=1e-12, abs=1e-12), row


def test_track_prints_a_path_that_opens_as_printed(tmp_path: Path):
    """A real `photoservo track` process with the default path: the `recording:` line it prints
    names one file that `rerun rrd verify`, `rerun rrd stats` and `photoservo replay` open."""
    import subprocess
    import sys

    from photoservo.record.files import rerun_cli

    logs = tmp_path / "logs"
    r = subprocess.run([sys.executable, "-m", "photoservo.cli", "track", *SHORT, "--seed", "3",
                        "--set", f"recording.dir='{logs}'"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    printed = [ln.split("recording: ", 1)[1] for ln in r.stdout.splitlines() if ln.startswith("recording: ")]
    assert len(printed) == 1 and Path(printed[0]).parent == logs
    assert [p.name for p in logs.iterdir()] == [Path(printed[0]).name]
    ok, msg = verify_rrd(printed[0])
    assert ok, msg
    stats = subprocess.run([str(rerun_cli()), "rrd", "stats", printed[0]], capture_output=True, text=True)
    assert stats.returncode == 0 and "num_chunks" in stats.stdout
    rep = subprocess.run([sys.executable, "-m", "photoservo.cli", "replay", printed[0], "--no-record"],
                         capture_output=True, text=True, timeout=600)
    assert rep.returncode == 0, rep.stderr[-2000:]
    assert "recording: none (--no-record)" in rep.stdout and len(list(logs.iterdir())) == 1


@pytest.fixture(scope="module")
def recorded_full(tmp_path_factory) -> Path:
    """The same lockstep run as `recorded`, with full frames."""
    path = tmp_path_factory.mktemp("rec") / "full.rrd"
    assert main(["track", *SHORT, "--seed", "3", "--record", str(path), "--set", "recording.mode='full'"]) == 0
    return path


def test_compact_replays_tracker_ga_servo_changes_exactly_as_full_frames(recorded: Path, recorded_full: Path,
                                                                          tmp_path: Path):
    """Issue 13's budget: the compact recording keeps what the tracker reads, so a replay with
    other tracker, GA, estimator, fitness-weight and servo keys gives bit for bit what the full
    frames give (acquisition with its stereo plane fit included)."""
    from photoservo.config import load_config
    from photoservo.record.planes import hue_class_lut, tracker_planes
    from photoservo.vision.fitness import stereo_hue

    a = read_recording(recorded)
    fit = load_config(recorded=("r", tomllib.loads(a.setup.config_toml))).fitness
    lut = hue_class_lut(a.setup.model.inner_hue, a.setup.model.target_hues, fit.hue_tolerance)
    for fc, ff in zip(iter_frames(recorded), iter_frames(recorded_full)):   # the same session
        want = tracker_planes(stereo_hue(ff.left, ff.right, fit), ff.left, ff.right, lut, a.setup.model.target_hues)
        assert all(np.array_equal(fc.planes[k], want[k]) for k in want)
    keys = ["ga.population=12", "tracker.generations_per_frame=3", "tracker.gain_position=0.5",
            "estimator.min_contrast=0.6", "fitness.w_outer_mismatch=0.7", "servo.k_position=0.3"]
    rc = replay(load_replay(recorded, overrides=keys), record=False)
    rf = replay(load_replay(recorded_full, overrides=keys), record=False)
    assert rc.frames == rf.frames and rc.frames[0].found
    assert np.array_equal(rc.commands, rf.commands)
    assert [f.fitness for f in rc.frames] != [e.fitness for e in a.estimates]   # the keys changed the run
    # hue and photo-model keys: only the full frames can change them
    hue = replay(load_replay(recorded_full, overrides=["fitness.hue_tolerance=3"]), record=False)
    assert [f.fitness for f in hue.frames] != [f.fitness for f in rf.frames]
    for key in ("fitness.hue_tolerance=3", "photo_model.interval_px=6.0", "fitness.min_value=60"):
        with pytest.raises(InputError, match=f"{key.split('=')[0]} cannot change.*recording.mode"):
            load_replay(recorded, overrides=[key])


def test_truncated_recording_is_refused_unless_allow_partial(tmp_path: Path, capsys, monkeypatch):
    """Issue 12: a recording whose writer was killed (no footer, cut inside a message) says what
    is missing and how much was read, exit 2; --allow-partial replays what is there."""
    # rerun's batcher writes a chunk every BATCH_S of wall time: a fast machine writes this short
    # run as one chunk at close, so flush often, as a long session's file is written
    from photoservo.record import recorder
    monkeypatch.setattr(recorder, "BATCH_S", 0.02)
    recorded = tmp_path / "run.rrd"
    assert main(["track", *SHORT, "--seed", "3", "--record", str(recorded)]) == 0
    capsys.readouterr()
    data = recorded.read_bytes()
    cut = tmp_path / "cut.rrd"
    cut.write_bytes(data[: int(len(data) * 0.5)])  # (the last quarter can be all close-time flushes)
    part = read_recording(cut)
    n = len(part.frames)
    assert 1 <= n < 6 and part.truncated.startswith("no RRD footer")
    _one_line_error(["replay", str(cut), "--no-record"], capsys, "cut.rrd", "truncated recording",
                    "no RRD footer", f"read {n} frames", "--allow-partial")
    assert main(["replay", str(cut), "--no-record", "--allow-partial", "--json"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["frames"] <= n and "truncated recording" in err
    _one_line_error(["track", "--sim", "--world-from", str(cut), "--no-record"], capsys, "truncated recording")
    _one_line_error(["track", "--sim", "--allow-partial"], capsys, "--allow-partial", "--world-from")


def test_world_from_no_record_prints_no_path(recorded: Path, capsys):
    assert main(["track", "--sim", "--world-from", str(recorded), "--no-record", "--duration", "0.4"]) == 0
    out = capsys.readouterr().out
    assert "this run" in out and "recording:" not in out


def test_sigkill_ten_seconds_into_a_twenty_second_session_leaves_a_replayable_recording(tmp_path: Path):
    """Issue 13: a hard kill loses at most the last seconds. A real `track --sim` process is
    SIGKILLed 10 s into a 20 s session (lockstep, 3 fps: its clock does not depend on the
    machine's load, as the real-time simulator's does); its one file is readable past 5 s,
    `replay` says it is truncated (exit 2) and replays it with --allow-partial."""
    import os
    import signal
    import subprocess
    import sys
    import time

    path = tmp_path / "killed.rrd"
    proc = subprocess.Popen([sys.executable, "-m", "photoservo.cli", "track", "--sim", "--lockstep", "--duration",
                             "20", "--record", str(path), "--set", "sim.camera_fps=3.0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 300
        t = 0.0
        while t < 10.0:   # the status line: "t  10.0 s | ..." once a second without a terminal
            line = proc.stderr.readline()
            assert line and time.monotonic() < deadline, "track ended or stalled before 10 s"
            if line.startswith("t "):
                t = float(line.split()[1])
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)   # anything it started, orphaned
        except ProcessLookupError:
            pass
        proc.wait()
        proc.stdout.close()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    assert [p.name for p in tmp_path.iterdir()] == ["killed.rrd"]
    rec = read_recording(path)
    assert rec.truncated is not None and rec.frames and rec.frames[-1].t >= 5.0, [f.t for f in rec.frames][-3:]
    assert rec.arm["q"].t[-1] >= 5.0
    r = subprocess.run([sys.executable, "-m", "photoservo.cli", "replay", str(path), "--no-record"],
                       capture_output=True, text=True, timeout=600)
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and "truncated recording" in err[0], r.stderr
    r = subprocess.run([sys.executable, "-m", "photoservo.cli", "replay", str(path), "--no-record",
                        "--allow-partial", "--json"], capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    assert json.loads(r.stdout)["frames"] == len(list(iter_frames(path))) >= 1


def test_setpoints_are_logged_with_their_units_and_signs(recorded: Path):
    """arm/setpoint_deg holds joint positions and arm/command_deg_s joint velocities (read back
    in rad and rad/s): the positions' finite differences over the 50 Hz log agree with the velocities in sign and
    size, and the positions stay by the measured joints."""
    r = read_recording(recorded)
    sq, sd, q = r.arm["setpoint"], r.arm["command"], r.arm["q"]
    assert set(r.arm) == {"q", "setpoint", "command"}
    assert np.array_equal(sq.t, sd.t) and np.array_equal(sq.t, q.t)
    assert np.abs(sq.values - q.values).max() < 0.01           # rad: a period's step from the state
    v = np.diff(sq.values, axis=0) / np.diff(sq.t)[:, None]    # rad/s
    mid = 0.5 * (sd.values[1:] + sd.values[:-1])
    moving = np.abs(mid) > 0.02
    assert moving.sum() > 10
    assert np.mean(np.sign(v[moving]) == np.sign(mid[moving])) > 0.95
    assert np.median(np.abs(v[moving] - mid[moving]) / np.abs(mid[moving])) < 0.2


def test_a_recording_made_before_a_photo_model_field_replays_on_the_model_rebuilt_from_its_photo(
        recorded: Path, tmp_path: Path, monkeypatch):
    """A recording whose photo-model npz lacks a field the PhotoModel has now (here
    `inner_saturation`, as every recording made before that field was added): the reader leaves the
    model out with a warning, and `load_replay` rebuilds it from the recorded photo and config, equal
    field by field to the model the run used, so the recording still replays."""
    import io
    from photoservo.record import drawing

    def pack_without_saturation(model) -> bytes:
        arrays = {f.name: np.asarray(getattr(model, f.name)) for f in dataclasses.fields(model)
                  if f.name != "inner_saturation"}
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        return buf.getvalue()

    a = read_recording(recorded)
    old = tmp_path / "old.rrd"
    monkeypatch.setattr(drawing, "pack_model", pack_without_saturation)
    _relog(recorded, old, a.setup.config_toml, generations=8)
    monkeypatch.undo()
    with pytest.warns(UserWarning, match="inner_saturation"):
        assert read_recording(old).setup.model is None
    with pytest.warns(UserWarning, match="inner_saturation"):
        setup = load_replay(old)
    for f in dataclasses.fields(a.setup.model):
        assert np.array_equal(np.asarray(getattr(setup.model, f.name)), np.asarray(getattr(a.setup.model, f.name))), f.name
    assert setup.model.inner_saturation.size == setup.model.inner_uv.shape[0] > 0
    assert len(replay(setup, tmp_path / "r.rrd").frames) == 6
