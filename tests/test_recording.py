"""Recordings (issue 6): frames and setup read back exactly, files complete after exceptions,
Ctrl-C and hard kills (checked with the real `rerun rrd verify`), the comparison table against
hand-computed numbers."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

from photoservo.errors import InputError
from photoservo.geometry import make_pose
from photoservo.record.recorder import (
    PREVIEW_WARNING,
    Recorder,
    default_path,
    rerun_cli,
    segment_path,
    verify_rrd,
)
from photoservo.record.reader import (
    compare_runs,
    iter_frames,
    read_recording,
    recording_files,
    run_metrics,
)
from photoservo.vision.estimator import Estimate
from photoservo.vision.photo_model import PhotoModel
from photoservo.vision.rig import default_rig, dump_rig, parse_rig

W, H = 64, 48


def frame_pair(k: int) -> tuple[np.ndarray, np.ndarray]:
    """Seeded noise frames: every bit matters, so only a lossless path reads them back."""
    rng = np.random.default_rng(1000 + k)
    return (rng.integers(0, 256, (H, W, 3), dtype=np.uint8),
            rng.integers(0, 256, (H, W, 3), dtype=np.uint8))


def small_model() -> PhotoModel:
    rng = np.random.default_rng(5)
    return PhotoModel(inner_uv=rng.normal(0, 9, (40, 2)), inner_hue=rng.integers(0, 180, 40).astype(np.uint8),
                      outer_uv=rng.normal(0, 15, (25, 2)), target_hues=rng.random(180) < 0.2,
                      size_px=(31.5, 17.25), origin_px=(30.0, 22.5),
                      mask=(rng.random((H, W)) < 0.3).astype(np.uint8) * 255)


CONFIG_TOML = "[photo_model]\ninterval_px = 4.0\n"


def test_verify_cli_is_shipped():
    assert rerun_cli().is_file(), "the rerun-sdk wheel should install a `rerun` executable"


@pytest.mark.parametrize("mode", ["lossless", "png"])
def test_frames_and_static_setup_read_back_exactly(tmp_path: Path, mode: str):
    path = tmp_path / "run.rrd"
    model, rig = small_model(), default_rig()
    photo = frame_pair(99)[0]
    T = np.eye(4)
    T[:3, 3] = (1.5, -2.0, 600.0)
    with Recorder.open(path, "track", mode=mode) as rec:
        rec.log_static_setup(dump_rig(rig), photo, model, CONFIG_TOML, seed=1234)
        for k in range(5):
            rec.log_frame(k, 0.1 + k / 30, *frame_pair(k), T_base_left=T,
                          capture_times=(0.1 + k / 30 - 0.002, 0.1 + k / 30 - 0.001))
    assert verify_rrd(path)[0]
    r = read_recording(path, images=True)
    assert [f.index for f in r.images] == list(range(5))
    for f in r.images:
        left, right = frame_pair(f.index)
        assert np.array_equal(f.left, left) and np.array_equal(f.right, right)
        assert f.t == pytest.approx(0.1 + f.index / 30, abs=1e-9)
    assert np.array_equal(r.frames[2].T_base_left, T)
    assert r.frames[2].capture_times == pytest.approx((0.1 + 2 / 30 - 0.002, 0.1 + 2 / 30 - 0.001))
    s = r.setup
    assert s.seed == 1234 and s.replayable and s.run["verb"] == "track" and s.run["mode"] == mode
    assert s.versions["rerun"].startswith("0.41")
    assert s.config_toml == CONFIG_TOML
    rig2 = parse_rig(tomllib.loads(s.rig_toml))
    assert np.array_equal(s.rig().right.K, rig.right.K)
    assert np.array_equal(rig2.left.K, rig.left.K) and np.array_equal(rig2.T, rig.T)
    assert np.array_equal(s.photo_bgr, photo)
    for name in ("inner_uv", "inner_hue", "outer_uv", "target_hues", "mask"):
        a, b = getattr(s.model, name), getattr(model, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert s.model.size_px == model.size_px and s.model.origin_px == model.origin_px


def test_estimates_arm_timings_events_read_back(tmp_path: Path):
    path = tmp_path / "run.rrd"
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    with Recorder.open(path, "track") as rec:
        rec.log_estimate(0, 0.0, found=False, fitness=0.125)
        rec.log_estimate_of(2, 0.1, Estimate(found=False, position_mm=None, rotation=None,
                                             alpha_px_per_mm=None, size_mm=None, fitness=None,
                                             generations=4, seconds=0.01, confidence=0.0))
        rec.log_estimate(1, 0.05, found=True, fitness=0.875, R=R, position_mm=[1.0, 2.0, 503.25],
                         alpha=2.5, size_mm=(40.0, 20.0), generations=7)
        for i in range(3):
            rec.log_arm(0.01 * i, np.full(7, 0.1 * i), np.full(7, 0.2 * i), np.full(7, 0.3 * i))
        rec.log_timings(0.05, {"capture": 1.5, "ga": 20.25})
        rec.event(0.05, "target found")
    r = read_recording(path)
    e0, e1, e2 = r.estimates
    assert (e2.frame, e2.found, e2.fitness, e2.generations, e2.position_mm) == (2, False, None, 4, None)
    assert (e0.frame, e0.found, e0.fitness, e0.rotation) == (0, False, 0.125, None)
    assert (e1.found, e1.fitness, e1.alpha, e1.generations) == (True, 0.875, 2.5, 7)
    assert np.array_equal(e1.rotation, R) and np.array_equal(e1.position_mm, [1.0, 2.0, 503.25])
    assert np.array_equal(e1.size_mm, [40.0, 20.0])
    assert np.allclose(r.arm["command"].values, [[0.0] * 7, [0.3] * 7, [0.6] * 7])
    assert np.allclose(r.arm["q"].t, [0.0, 0.01, 0.02])
    assert r.timings["ga"].values[0, 0] == 20.25 and r.timings["capture"].values[0, 0] == 1.5
    assert (0.05, "INFO", "target found") in r.events


def test_preview_mode_says_it_cannot_be_replayed(tmp_path: Path):
    path = tmp_path / "long.rrd"
    with pytest.warns(UserWarning, match="CANNOT be replayed"), \
            Recorder.open(path, "track", mode="preview") as rec:
        rec.log_frame(0, 0.0, *frame_pair(0))
    r = read_recording(path, images=True)
    assert not r.setup.replayable and r.setup.warning == PREVIEW_WARNING
    assert any(PREVIEW_WARNING in text for _, _, text in r.events)
    assert r.images[0].left.shape == (H, W, 3)     # viewable, but not equal: JPEG
    assert not np.array_equal(r.images[0].left, frame_pair(0)[0])


def test_exception_inside_the_block_leaves_a_verified_file(tmp_path: Path):
    path = tmp_path / "crash.rrd"
    with pytest.raises(ZeroDivisionError), Recorder.open(path, "track") as rec:
        for k in range(4):
            rec.log_frame(k, k / 30, *frame_pair(k))
        _ = 1 / 0
    ok, msg = verify_rrd(path)
    assert ok, msg
    r = read_recording(path, images=True)
    assert len(r.images) == 4 and np.array_equal(r.images[3].right, frame_pair(3)[1])
    assert any("ZeroDivisionError" in text for _, _, text in r.events)


def test_segments_close_cleanly_and_read_as_one(tmp_path: Path):
    base = tmp_path / "seg.rrd"
    with Recorder.open(base, "track", segment_s=0.1) as rec:   # 3 frames per segment at 30 fps
        rec.log_static_setup(dump_rig(default_rig()), None, None, CONFIG_TOML, seed=9)
        for k in range(10):
            rec.log_frame(k, k / 30, *frame_pair(k))
            rec.log_estimate(k, k / 30, found=True, fitness=k / 10, R=np.eye(3),
                             position_mm=[0, 0, 500.0], alpha=2.0)
    files = recording_files(base)
    assert files == [segment_path(base, i) for i in (1, 2, 3, 4)] == rec.files
    assert not base.exists()
    from rerun.chunk import RrdReader
    for f in files:
        assert verify_rrd(f)[0], f
        assert len(RrdReader(f).blueprints()) == 1     # the layout goes with every file
        assert [e.recording_id for e in RrdReader(f).recordings()] == [rec.recording_id]
        one = read_recording(f)                        # each segment stands alone...
        assert one.setup.seed == 9 and one.setup.config_toml == CONFIG_TOML
    r = read_recording(segment_path(base, 2))          # ...and any segment names the whole
    assert r.files == files and not r.incomplete
    assert [e.frame for e in r.estimates] == list(range(10))
    frames = list(iter_frames(base))
    assert [f.index for f in frames] == list(range(10))
    assert all(np.array_equal(f.left, frame_pair(f.index)[0]) for f in frames)


CHILD = r"""
import sys, time
import numpy as np
sys.path.insert(0, sys.argv[3])
from test_recording import frame_pair
from photoservo.record.recorder import Recorder
path, segment_s = sys.argv[1], float(sys.argv[2])
with Recorder.open(path, "track", segment_s=segment_s) as rec:
    rec.log_static_setup(None, None, None, "[x]\n", seed={"ga": 3, "world": 4})
    k = 0
    while True:
        rec.log_frame(k, k / 30, *frame_pair(k))
        print("frame", k, rec.segment_index, flush=True)
        k += 1
        time.sleep(0.005)
"""


def _start_child(path: Path, segment_s: float) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", CHILD, str(path), str(segment_s),
                             str(Path(__file__).parent)], stdout=subprocess.PIPE, text=True)


def _wait_for(proc: subprocess.Popen, pred) -> None:
    deadline = time.monotonic() + 60
    for line in proc.stdout:
        _, k, files = line.split()
        if pred(int(k), int(files)):
            return
        assert time.monotonic() < deadline, "child too slow"
    raise AssertionError(f"child ended early with {proc.wait()}")


def test_sigint_leaves_a_verified_file(tmp_path: Path):
    path = tmp_path / "ctrl_c.rrd"
    proc = _start_child(path, 0.0)
    try:
        _wait_for(proc, lambda k, n: k >= 10)
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=60)
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
    assert proc.returncode != 0                          # KeyboardInterrupt went through
    ok, msg = verify_rrd(path)
    assert ok, msg
    r = read_recording(path, images=True)
    assert [f.index for f in r.images] == list(range(len(r.images))) and len(r.images) >= 11
    assert any("KeyboardInterrupt" in text for _, _, text in r.events)


def test_hard_kill_leaves_verified_segments_read_as_one(tmp_path: Path):
    base = tmp_path / "killed.rrd"
    proc = _start_child(base, 0.2)                       # 6 frames per segment
    try:
        _wait_for(proc, lambda k, n: n >= 4)
        time.sleep(0.05)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
    files = recording_files(base)
    finished = [f for f in files if not f.name.endswith(".partial.rrd")]
    assert len(finished) >= 3 and files[:len(finished)] == finished
    assert len(files) - len(finished) <= 2               # the tail (2 if killed mid-rotation)
    for f in finished:                                   # every finished segment verifies
        ok, msg = verify_rrd(f)
        assert ok, f"{f.name}: {msg}"
    r = read_recording(base, images=True)
    assert set(r.incomplete) == set(files) - set(finished)
    n = len(r.images)
    assert n >= 6 * len(finished)                        # at least all finished segments
    assert [f.index for f in r.images] == list(range(n))
    assert all(np.array_equal(f.right, frame_pair(f.index)[1]) for f in r.images)
    assert r.setup.seed == {"ga": 3, "world": 4}


def _Rx(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _Rz(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_comparison_table_against_hand_computed_numbers(tmp_path: Path):
    # Camera 1000 mm above the base origin looking straight down: x_base = x_cam,
    # y_base = -y_cam, z_base = 1000 - z_cam.
    down = np.diag([1.0, -1.0, -1.0])
    T_base_left = make_pose(down, [0, 0, 1000.0])
    a = tmp_path / "a.rrd"
    with Recorder.open(a, "track") as rec:
        cam_x = [0.0, 10.0, 30.0]
        truths = [make_pose(down, [0, 0, 500]), make_pose(_Rx(5) @ down, [10, 3, 504]),
                  make_pose(_Rz(10) @ down, [30, 0, 500])]
        sizes = [(20, 10), (22, 10), (20, 13)]
        for k, fit in enumerate([0.8, 0.6, 0.7, 0.1]):
            t = 0.04 * k
            rec.log_frame(k, t, *frame_pair(k))
            if k < 3:
                rec.log_estimate(k, t, found=True, fitness=fit, R=np.eye(3), alpha=2.0,
                                 position_mm=[cam_x[k], 0, 500], size_mm=(20, 10),
                                 T_base_left=T_base_left)
                rec.log_truth(k, t, truths[k], sizes[k])
            else:
                rec.log_estimate(k, t, found=False, fitness=fit)
        for t, c in [(0.0, [0] * 7), (0.01, [0.3, 0.4, 0, 0, 0, 0, 0]),
                     (0.02, [0.3, 0.4, 1.2, 0, 0, 0, 0])]:
            rec.log_arm(t, np.zeros(7), np.zeros(7), np.array(c, dtype=float))
    b = tmp_path / "b.rrd"
    with Recorder.open(b, "track") as rec:
        for k in range(3):
            rec.log_frame(k, 0.05 * k, *frame_pair(k))
            rec.log_estimate(k, 0.05 * k, found=True, fitness=0.9, R=np.eye(3),
                             position_mm=[0, 0, 400.0 + 7 * k * k], alpha=2.0)
    ra = read_recording(a)
    m = run_metrics(ra)
    expect = {"frames": 4, "mean_fitness": 0.55, "found_ratio": 0.75, "lost_frames": 1,
              "jitter_mm": 10.0,                      # |30 - 2*10 + 0|
              "ms_per_frame": 40.0, "commanded_rad": 0.5 + 1.2,
              "pos_err_mm": math.sqrt(25 / 3),        # errors 0, |(0,-3,-4)| = 5, 0
              "heading_err_deg": math.sqrt(100 / 3),  # 0, 0, 10 deg
              "tilt_err_deg": math.sqrt(25 / 3),      # 0, 5, 0 deg
              "size_err_mm": math.sqrt((0 + 1 + 1.5 ** 2) / 3)}
    for k, v in expect.items():
        assert m[k] == pytest.approx(v, rel=1e-6, abs=1e-6), k
    table = compare_runs(ra, b, "recorded", "replay")                  # a run or a path
    assert table.row("mean_fitness").b == pytest.approx(0.9)
    assert table.row("jitter_mm").b == pytest.approx(14.0)   # z: 400, 407, 428 -> 14
    assert table.row("ms_per_frame").delta == pytest.approx(10.0)
    assert math.isnan(table.row("pos_err_mm").b) and math.isnan(table.row("commanded_rad").b)
    text = str(table)
    assert "pose jitter (mm)" in text and "recorded" in text and "replay" in text
    assert text.splitlines()[2].split()[-3:] == ["4", "3", "-1"]   # frames row


def test_bad_inputs_are_one_line_errors(tmp_path: Path):
    with pytest.raises(InputError, match="mode 'tiff'"):
        Recorder.open(tmp_path / "x.rrd", "track", mode="tiff")
    with pytest.raises(InputError, match=r"\.rrd"):
        Recorder.open(tmp_path / "x.mp4", "track")
    with pytest.raises(InputError, match="recording not found"):
        read_recording(tmp_path / "missing.rrd")
    seg = tmp_path / "again.rrd"
    with Recorder.open(seg, "track", segment_s=1.0) as rec:
        rec.log_frame(0, 0.0, *frame_pair(0))
    with pytest.raises(InputError, match="exists already"):
        Recorder.open(seg, "track", segment_s=1.0)
    assert default_path("move", tmp_path).parent == tmp_path
    assert default_path("move").name.endswith("_move.rrd")


def test_live_stream_to_a_grpc_server_still_writes_the_file(tmp_path: Path):
    """`connect_url` tees to a running viewer; rerun's own gRPC server stands in for it (no
    viewer on this machine). The file and its segments stay complete, and closing is prompt."""
    import socket
    import uuid

    import rerun as rr
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = rr.RecordingStream("viewer-stand-in", recording_id=uuid.uuid4())
    url = server.serve_grpc(grpc_port=port)
    try:
        t0 = time.monotonic()
        with Recorder.open(tmp_path / "live.rrd", "track", connect_url=url, segment_s=0.1) as rec:
            for k in range(8):
                rec.log_frame(k, k / 30, *frame_pair(k))
        assert time.monotonic() - t0 < 5.0
    finally:
        server.disconnect()
    assert len(rec.files) == 3 and all(verify_rrd(f)[0] for f in rec.files)
    frames = list(iter_frames(tmp_path / "live.rrd"))
    assert [f.index for f in frames] == list(range(8))


def test_arm_samples_from_a_control_thread_are_all_written(tmp_path: Path):
    """`move` logs only the arm, at the control rate, from its own thread: every sample lands,
    in order, with the arm drawn and the flange path written."""
    import threading

    from rerun.chunk import RrdReader
    path = tmp_path / "move.rrd"
    n = 600                                                  # > ARM_BATCH: flushed mid-run too
    with Recorder.open(path, "move") as rec:
        def control() -> None:
            for i in range(n):
                rec.log_arm(i * 0.002, np.full(7, i * 1e-3), np.full(7, i * 2e-3), np.full(7, i * 3e-3))
        th = threading.Thread(target=control)
        th.start()
        th.join()
    assert verify_rrd(path)[0]
    r = read_recording(path)
    assert np.allclose(r.arm["q"].t, np.arange(n) * 0.002)
    assert np.allclose(r.arm["setpoint"].values[:, 3], np.arange(n) * 2e-3)
    assert r.arm["command"].values.shape == (n, 7)
    entities = {c.entity_path for c in RrdReader(path).stream()}
    assert {"/world/arm/link7", "/world/arm/skeleton", "/world/flange/path"} <= entities


def test_projected_points_and_desired_pose_are_drawn(tmp_path: Path):
    from rerun.chunk import RrdReader

    from photoservo.vision.fitness import project_model
    model, rig = small_model(), default_rig()
    R, p, alpha = np.eye(3), np.array([0.0, 0.0, 400.0]), 4.0
    proj = project_model(R, p, alpha, model, rig)
    path = tmp_path / "drawn.rrd"
    with Recorder.open(path, "track") as rec:
        rec.log_static_setup(dump_rig(rig), frame_pair(0)[0], model, CONFIG_TOML, seed=1)
        rec.log_frame(0, 0.0, *frame_pair(0))
        est = Estimate(found=True, position_mm=p, rotation=R, alpha_px_per_mm=alpha,
                       size_mm=model.size_mm(alpha), fitness=0.7, generations=9, seconds=0.02,
                       confidence=0.9)
        rec.log_estimate_of(0, 0.0, est, projection=proj)
        rec.log_desired(0.0, np.eye(4), frame=0)
    assert verify_rrd(path)[0]
    pts, ids = {}, {}
    for c in RrdReader(path).stream():
        rb = c.to_record_batch()
        if "Points2D:positions" in rb.schema.names and not c.is_static:
            pts[c.entity_path] = np.array(rb.column("Points2D:positions")[0].values.to_pylist())
            ids[c.entity_path] = np.array(rb.column("Points2D:class_ids")[0].values.to_pylist())
    assert set(pts) == {"/world/rig/left/model", "/world/rig/right/model"}
    left, right = pts["/world/rig/left/model"], ids["/world/rig/right/model"]
    n_in = len(model.inner_uv)
    assert np.allclose(left[:n_in], proj.inner_left[0], atol=1e-3)             # float32
    assert np.allclose(left[n_in:], proj.outer_left[0], atol=1e-3)
    assert (right == 0).sum() == n_in and (right == 1).sum() == len(model.outer_uv)
    e = read_recording(path).estimates[0]
    assert (e.found, e.fitness, e.alpha, e.generations) == (True, 0.7, alpha, 9)
    assert np.array_equal(e.size_mm, model.size_mm(alpha))


def test_recording_config_section(tmp_path: Path):
    from photoservo.config import load_config
    cfg = load_config(overrides=["recording.segment_s=0.1", f"recording.dir='{tmp_path}'"]).recording
    assert cfg.mode == "lossless"
    with Recorder.from_config(cfg, "move") as rec:
        rec.log_frame(0, 0.0, *frame_pair(0))
        rec.log_frame(1, 0.2, *frame_pair(1))
    assert [f.parent for f in rec.files] == [tmp_path, tmp_path] and rec.files[0].name.endswith("_move.seg0001.rrd")
    with pytest.raises(InputError, match="recording.segment_s"):
        load_config(overrides=["recording.segment_s=-1"])


def test_a_segment_cut_inside_a_message_is_read_up_to_its_last_complete_message(tmp_path: Path):
    """What a SIGKILL during a write leaves: rerun refuses such a file outright; the reader
    salvages every complete message before the cut."""
    whole = tmp_path / "whole.rrd"
    with Recorder.open(whole, "track") as rec:
        rec.log_static_setup(None, None, None, CONFIG_TOML, seed=2)
        for k in range(12):
            rec.log_frame(k, k / 30, *frame_pair(k))
            rec._rec.flush()                                 # one message per frame, in order
    data = whole.read_bytes()
    cut = segment_path(tmp_path / "cut.rrd", 1, partial=True)
    cut.write_bytes(data[: len(data) // 2 + 7])              # mid-message
    r = read_recording(tmp_path / "cut.rrd", images=True)
    assert r.incomplete == [cut] and r.setup.seed == 2
    n = len(r.images)
    assert 3 <= n < 12 and [f.index for f in r.images] == list(range(n))
    assert all(np.array_equal(f.left, frame_pair(f.index)[0]) for f in r.images)
