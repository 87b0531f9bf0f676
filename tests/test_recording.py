"""Recordings (issues 6, 12, 13): frames, planes and setup read back exactly, one file under the
given name, complete after exceptions and Ctrl-C (checked with the real `rerun rrd verify`), read
as far as it goes after a hard kill and reported truncated, none for a run that never started;
the comparison table against hand-computed numbers."""

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
from photoservo.record.compare import compare_runs, run_metrics
from photoservo.record.planes import tracker_planes
from photoservo.record.reader import describe_truncation, iter_frames, read_recording
from photoservo.record.files import default_path, rerun_cli, verify_rrd
from photoservo.record.recorder import PREVIEW_WARNING, Recorder
from photoservo.vision.fitness import stereo_hue
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


def test_full_frames_and_static_setup_read_back_exactly(tmp_path: Path):
    path = tmp_path / "run.rrd"
    model, rig = small_model(), default_rig()
    photo = frame_pair(99)[0]
    T = np.eye(4)
    T[:3, 3] = (1.5, -2.0, 600.0)
    with Recorder.open(path, "track", mode="full") as rec:
        rec.log_static_setup(dump_rig(rig), photo, model, CONFIG_TOML, seed=1234)
        for k in range(5):
            rec.log_frame(k, 0.1 + k / 30, *frame_pair(k), T_base_left=T,
                          capture_times=(0.1 + k / 30 - 0.002, 0.1 + k / 30 - 0.001))
    assert verify_rrd(path)[0]
    r = read_recording(path, images=True)
    assert [f.index for f in r.images] == list(range(5)) and r.truncated is None
    for f in r.images:
        left, right = frame_pair(f.index)
        assert np.array_equal(f.left, left) and np.array_equal(f.right, right)
        assert f.t == pytest.approx(0.1 + f.index / 30, abs=1e-9)
    assert np.array_equal(r.frames[2].T_base_left, T)
    assert r.frames[2].capture_times == pytest.approx((0.1 + 2 / 30 - 0.002, 0.1 + 2 / 30 - 0.001))
    s = r.setup
    assert s.seed == 1234 and s.replayable and s.full_frames
    assert s.run["verb"] == "track" and s.run["mode"] == "full" and s.run["format"] == 2
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


@pytest.mark.parametrize("video", ["av1", "h264", "none"])
def test_compact_mode_keeps_the_tracker_planes_exactly_and_a_video(tmp_path: Path, video: str):
    """Compact: per frame the planes the tracker reads (hue classes, grey near target hue)
    exactly, given by the loop or computed from the frames; a decodable video per camera."""
    from photoservo.config import load_config
    from photoservo.record.planes import hue_class_lut
    from photoservo.record.video import decode_samples

    path = tmp_path / "compact.rrd"
    model, fit = small_model(), load_config().fitness
    with Recorder.open(path, "track", mode="compact", video=video) as rec:
        rec.log_static_setup(dump_rig(default_rig()), None, model, CONFIG_TOML, seed=7)
        for k in range(6):
            hue = stereo_hue(*frame_pair(k), fit)
            rec.log_frame(k, k / 30, *frame_pair(k), fitness_input=hue if k % 2 else None)
    assert verify_rrd(path)[0]
    r = read_recording(path, images=True)
    assert not r.setup.full_frames and r.setup.replayable and r.setup.run["video"] == video
    lut = hue_class_lut(model.inner_hue, model.target_hues, fit.hue_tolerance)
    assert [f.index for f in r.images] == list(range(6))
    for f in r.images:
        want = tracker_planes(stereo_hue(*frame_pair(f.index), fit), *frame_pair(f.index), lut, model.target_hues)
        assert f.left is None and sorted(f.planes) == sorted(want)
        assert all(np.array_equal(f.planes[n], want[n]) for n in want)
    if video == "none":
        assert all(not f.video for f in r.images)
        return
    for side in ("left", "right"):
        samples = [s for f in r.images for s in f.video[side]]
        assert [s.frame for s in samples] == list(range(6)) and samples[0].keyframe
        frames = decode_samples(video, [s.data for s in samples])
        assert len(frames) == 6 and frames[0].shape[:2] == (64, 64)   # padded to the encoder's minimum


def test_video_fps_keeps_one_frame_per_slot_on_both_cameras_and_every_plane(tmp_path: Path):
    """[recording] video_fps 10 at 30 fps frames: the video keeps frames 0, 3, 6, ... (the first
    in each 0.1 s slot, the same on both cameras, decodable), the planes keep every frame."""
    from photoservo.record.video import decode_samples

    path = tmp_path / "tenhz.rrd"
    with Recorder.open(path, "track", mode="compact", video="av1", video_fps=10.0) as rec:
        rec.log_static_setup(dump_rig(default_rig()), None, small_model(), CONFIG_TOML, seed=7)
        for k in range(10):
            rec.log_frame(k, 0.001 + k / 30, *frame_pair(k))
    r = read_recording(path, images=True)
    assert [f.index for f in r.images] == list(range(10)) and all(f.planes for f in r.images)
    assert r.setup.run["video_fps"] == 10.0
    for side in ("left", "right"):
        samples = [s for f in r.images for s in f.video.get(side, [])]
        assert [s.frame for s in samples] == [0, 3, 6, 9] and samples[0].keyframe
        assert len(decode_samples("av1", [s.data for s in samples])) == 4
    with pytest.raises(InputError, match="video_fps -1"):
        Recorder.open(tmp_path / "bad.rrd", "track", video_fps=-1.0)


def test_a_video_encoder_behind_leaves_frames_out_of_the_video_never_out_of_the_planes(tmp_path: Path):
    """The video worker held up (as on a machine short of CPU): frames more than VIDEO_LAG_S of
    loop time after the oldest waiting one are left out of the video and counted in a WARN
    event; the loop is not held up and every frame's planes are kept."""
    import threading
    from photoservo.record.encoding import VIDEO_LAG_S

    path, held = tmp_path / "behind.rrd", threading.Event()
    with Recorder.open(path, "track", mode="compact", video="av1") as rec:
        rec.log_static_setup(dump_rig(default_rig()), None, small_model(), CONFIG_TOML, seed=7)
        rec.encoding.workers["video"].queue.put(held.wait)
        t0 = time.perf_counter()
        for k in range(10):
            rec.log_frame(k, k / 10, *frame_pair(k))
        assert time.perf_counter() - t0 < 5.0     # the loop went on while the video worker waited
        held.set()
    r = read_recording(path, images=True)
    kept = [k for k in range(10) if k / 10 <= VIDEO_LAG_S]
    assert [f.index for f in r.images] == list(range(10)) and all(f.planes for f in r.images)
    for side in ("left", "right"):
        assert [s.frame for f in r.images for s in f.video.get(side, [])] == kept
    assert any(f"{10 - len(kept)} frames left out of the watch-only video" in text for _, level, text in r.events
               if level == "WARN")


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
    from photoservo.record.video import decode_samples

    path = tmp_path / "long.rrd"
    smooth = np.repeat(np.linspace(0, 255, W, dtype=np.uint8)[None, :, None], H, axis=0).repeat(3, axis=2)
    with pytest.warns(UserWarning, match="CANNOT be replayed"), \
            Recorder.open(path, "track", mode="preview") as rec:
        for k in range(3):
            rec.log_frame(k, k / 30, smooth, smooth)
    r = read_recording(path, images=True)
    assert not r.setup.replayable and r.setup.warning == PREVIEW_WARNING
    assert any(PREVIEW_WARNING in text for _, _, text in r.events)
    assert all(f.left is None and f.planes is None for f in r.images)      # watched only
    video = decode_samples("av1", [s.data for f in r.images for s in f.video["left"]])
    assert len(video) == 3 and np.abs(video[2][:H, :W].astype(int) - smooth).mean() < 4   # lossy, close


def test_no_file_for_a_run_that_never_started(tmp_path: Path):
    """The setup is buffered until the first frame or arm sample: a start that fails before the
    session leaves nothing behind."""
    path = tmp_path / "never.rrd"
    with pytest.raises(RuntimeError), Recorder.open(path, "track") as rec:
        rec.log_static_setup(dump_rig(default_rig()), None, small_model(), CONFIG_TOML, seed=1)
        rec.event(0.0, "starting")
        raise RuntimeError("the camera did not open")
    assert not rec.written and not path.exists() and list(tmp_path.iterdir()) == []
    with Recorder.open(path, "move") as rec:                 # the first arm sample starts it
        rec.event(0.0, "before the session")
        rec.log_arm(0.0, np.zeros(7))
    assert rec.written and verify_rrd(path)[0]
    assert (0.0, "INFO", "before the session") in read_recording(path).events


def test_exception_inside_the_block_leaves_a_verified_file(tmp_path: Path):
    path = tmp_path / "crash.rrd"
    with pytest.raises(ZeroDivisionError), Recorder.open(path, "track", mode="full") as rec:
        for k in range(4):
            rec.log_frame(k, k / 30, *frame_pair(k))
        _ = 1 / 0
    ok, msg = verify_rrd(path)
    assert ok, msg
    r = read_recording(path, images=True)
    assert len(r.images) == 4 and np.array_equal(r.images[3].right, frame_pair(3)[1])
    assert any("ZeroDivisionError" in text for _, _, text in r.events)


# The child is a session a user stops with Ctrl-C: SIGINT raises KeyboardInterrupt there, however
# this test run was started. A background job (`cmd &`, a queue's) starts with SIGINT ignored, and
# a child started while the test process's SIGINT is ignored inherits that (Python then installs
# no KeyboardInterrupt handler): such children went on logging after the signal until the 60 s
# timeout (1724 frames in one case; a full suite run in the background failed only this test).
CHILD = r"""
import signal, sys, time
signal.signal(signal.SIGINT, signal.default_int_handler)
import numpy as np
sys.path.insert(0, sys.argv[2])
from test_recording import frame_pair
from photoservo.record.recorder import Recorder
with Recorder.open(sys.argv[1], "track", mode="full") as rec:
    rec.log_static_setup(None, None, None, "[x]\n", seed={"ga": 3, "world": 4})
    k = 0
    while True:
        rec.log_frame(k, k / 30, *frame_pair(k))
        print("frame", k, flush=True)
        k += 1
        time.sleep(1 / 30)
"""


def _start_child(path: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", CHILD, str(path), str(Path(__file__).parent)],
                            stdout=subprocess.PIPE, text=True)


def _wait_for(proc: subprocess.Popen, frames: int) -> int:
    deadline = time.monotonic() + 60
    for line in proc.stdout:
        k = int(line.split()[1])
        if k >= frames:
            return k
        assert time.monotonic() < deadline, "child too slow"
    raise AssertionError(f"child ended early with {proc.wait()}")


def test_sigint_leaves_a_verified_file(tmp_path: Path):
    path = tmp_path / "ctrl_c.rrd"
    proc = _start_child(path)
    try:
        _wait_for(proc, 10)
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


def test_hard_kill_leaves_the_file_readable_to_its_last_second_and_says_so(tmp_path: Path):
    path = tmp_path / "killed.rrd"
    proc = _start_child(path)
    try:
        last = _wait_for(proc, 150)                      # >= 5 s of frames at <= 30 fps
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
    assert path.is_file() and list(tmp_path.iterdir()) == [path]     # one file, the given name
    assert not verify_rrd(path)[0]                                    # no footer
    r = read_recording(path, images=True)
    assert r.truncated is not None and "no RRD footer" in r.truncated
    n = len(r.images)
    assert n >= last - 90                    # at most 3 s lost (BATCH_S = 1 s; the spec: 5 s)
    assert [f.index for f in r.images] == list(range(n))
    assert all(np.array_equal(f.right, frame_pair(f.index)[1]) for f in r.images)
    assert r.setup.seed == {"ga": 3, "world": 4}
    line = describe_truncation(r)
    assert line.startswith(f"{path}: truncated recording: no RRD footer") and f"read {len(r.frames)} frames" in line


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
              "ms_per_frame": 40.0, "commanded_rad_s": 0.5 + 1.2,
              "track_err_mm": math.sqrt(25 / 3),        # errors 0, |(0,-3,-4)| = 5, 0
              "heading_err_deg": math.sqrt(100 / 3),  # 0, 0, 10 deg
              "tilt_err_deg": math.sqrt(25 / 3),      # 0, 5, 0 deg
              "size_err_mm": math.sqrt((0 + 1 + 1.5 ** 2) / 3)}
    for k, v in expect.items():
        assert m[k] == pytest.approx(v, rel=1e-6, abs=1e-6), k
    table = compare_runs(ra, b, "recorded", "replay")                  # a run or a path
    assert table.row("mean_fitness").b == pytest.approx(0.9)
    assert table.row("jitter_mm").b == pytest.approx(14.0)   # z: 400, 407, 428 -> 14
    assert table.row("ms_per_frame").delta == pytest.approx(10.0)
    assert math.isnan(table.row("track_err_mm").b) and math.isnan(table.row("commanded_rad_s").b)
    text = str(table)
    assert "pose jitter (mm)" in text and "recorded" in text and "replay" in text
    assert text.splitlines()[2].split()[-3:] == ["4", "3", "-1"]   # frames row


def test_mean_fitness_leaves_out_frames_searched_in_vain(tmp_path: Path):
    # the tracker logs fitness -inf on a frame where its search found nothing: the mean is over
    # the frames that have a fitness (replay printed "mean fitness -inf" for any run with a miss)
    path = tmp_path / "m.rrd"
    with Recorder.open(path, "track") as rec:
        for k, (found, fit) in enumerate([(True, 0.8), (False, -math.inf), (True, 0.6)]):
            rec.log_frame(k, 0.04 * k, *frame_pair(k))
            rec.log_estimate(k, 0.04 * k, found=found, fitness=fit)
    m = run_metrics(read_recording(path))
    assert m["mean_fitness"] == pytest.approx(0.7) and m["found_ratio"] == pytest.approx(2 / 3)


def test_bad_inputs_are_one_line_errors(tmp_path: Path):
    with pytest.raises(InputError, match="mode 'tiff'"):
        Recorder.open(tmp_path / "x.rrd", "track", mode="tiff")
    with pytest.raises(InputError, match="video 'mpeg2'"):
        Recorder.open(tmp_path / "x.rrd", "track", video="mpeg2")
    with pytest.raises(InputError, match=r"\.rrd"):
        Recorder.open(tmp_path / "x.mp4", "track")
    with pytest.raises(InputError, match="recording not found"):
        read_recording(tmp_path / "missing.rrd")
    again = tmp_path / "again.rrd"
    with Recorder.open(again, "track") as rec:
        rec.log_frame(0, 0.0, *frame_pair(0))
    with pytest.raises(InputError, match="exists already"):
        Recorder.open(again, "track")


def test_default_paths_are_new_names_in_the_logs_folder(tmp_path: Path):
    from datetime import UTC, datetime
    now = datetime(2026, 11, 22, 4, 37, 0, tzinfo=UTC)
    first = default_path("move", tmp_path, now)
    assert first == tmp_path / "20261122T043700Z_move.rrd"
    first.write_bytes(b"taken")
    assert default_path("move", tmp_path, now) == tmp_path / "20261122T043700Z_move_2.rrd"
    assert default_path("move").parent == Path("logs") and default_path("move").name.endswith("_move.rrd")


def test_live_stream_to_a_grpc_server_still_writes_the_file(tmp_path: Path):
    """`connect_url` tees to a running viewer; rerun's own gRPC server stands in for it (no
    viewer on this machine). The file stays complete, and closing is prompt."""
    import socket
    import uuid

    import rerun as rr
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = rr.RecordingStream("viewer-stand-in", recording_id=uuid.uuid4())
    url = server.serve_grpc(grpc_port=port)
    path = tmp_path / "live.rrd"
    try:
        t0 = time.monotonic()
        with Recorder.open(path, "track", connect_url=url, mode="full") as rec:
            for k in range(8):
                rec.log_frame(k, k / 30, *frame_pair(k))
        assert time.monotonic() - t0 < 5.0
    finally:
        server.disconnect()
    assert verify_rrd(path)[0]
    frames = list(iter_frames(path))
    assert [f.index for f in frames] == list(range(8))


def test_arm_samples_from_a_control_thread_are_all_written_in_degrees(tmp_path: Path):
    """`move` logs only the arm, at the control rate, from its own thread: every sample lands,
    in order, with the arm drawn and the flange path written. The file holds degrees (the
    CLI's unit, what the viewer plots), the reader gives rad."""
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
    assert np.allclose(r.arm["setpoint"].values[:, 3], np.arange(n) * 2e-3, rtol=1e-12, atol=1e-15)
    assert r.arm["command"].values.shape == (n, 7)
    chunks = list(RrdReader(path).stream())
    assert {"/world/arm/link7", "/world/arm/skeleton", "/world/flange/path"} <= {c.entity_path for c in chunks}
    q_deg = np.concatenate([c.to_record_batch().column("Scalars:scalars").flatten().to_numpy()
                            for c in chunks if c.entity_path == "/arm/q_deg" and not c.is_static])
    assert np.allclose(np.sort(q_deg.reshape(-1, 7)[:, 0]), np.degrees(np.arange(n) * 1e-3))


@pytest.mark.parametrize("given", [True, False])
def test_projected_points_and_desired_pose_are_drawn(tmp_path: Path, given: bool):
    """Given a projection, or (as the session logs) projected by the recorder itself from the
    estimate's pose with the setup's photo-model and rig: the same points."""
    from rerun.chunk import RrdReader

    from photoservo.record.drawing import DRAW_POINTS
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
        rec.log_estimate_of(0, 0.0, est, projection=proj if given else None)
        rec.log_desired(0.0, np.eye(4), frame=0)
    assert verify_rrd(path)[0]
    pts = {}
    for c in RrdReader(path).stream():
        rb = c.to_record_batch()
        if "Points2D:positions" in rb.schema.names and not c.is_static:
            pts[c.entity_path] = np.array(rb.column("Points2D:positions")[0].values.to_pylist())
    assert set(pts) == {f"/world/rig/{s}/model/{k}" for s in ("left", "right") for k in ("inner", "outer")}
    assert len(model.inner_uv) <= DRAW_POINTS                               # all drawn
    assert np.allclose(pts["/world/rig/left/model/inner"], proj.inner_left[0], atol=1e-3)   # float32
    assert np.allclose(pts["/world/rig/right/model/outer"], proj.outer_right[0], atol=1e-3)
    e = read_recording(path).estimates[0]
    assert (e.found, e.fitness, e.alpha, e.generations) == (True, 0.7, alpha, 9)
    assert np.array_equal(e.size_mm, model.size_mm(alpha))


def test_pictures_are_drawn_at_the_video_rate_and_numbers_every_frame(tmp_path: Path):
    """Compact mode with a 10 Hz video, frames at 30 Hz: the rig pose, the pose boxes and the
    projected points of every third frame (the first of each 0.1 s, those of the video); the
    estimates and the truth of every frame."""
    from rerun.chunk import RrdReader

    from photoservo.vision.fitness import project_model
    model, rig = small_model(), default_rig()
    R, p, alpha = np.eye(3), np.array([0.0, 0.0, 400.0]), 4.0
    proj = project_model(R, p, alpha, model, rig)
    path = tmp_path / "rate.rrd"
    with Recorder.open(path, "track", video="none", video_fps=10.0) as rec:
        rec.log_static_setup(dump_rig(rig), frame_pair(0)[0], model, CONFIG_TOML, seed=1)
        for k in range(9):
            t = k / 30 + 0.001
            rec.log_frame(k, t, *frame_pair(k), T_base_left=np.eye(4))
            rec.log_estimate(k, t, found=True, fitness=0.7, R=R, position_mm=p, alpha=alpha,
                             size_mm=model.size_mm(alpha), T_base_left=np.eye(4), projection=proj)
            rec.log_truth(k, t, make_pose(R, p), model.size_mm(alpha))
    frames: dict[str, list[int]] = {}
    for c in RrdReader(path).stream():
        if not c.is_static and "frame" in c.to_record_batch().schema.names:
            frames.setdefault(c.entity_path, []).extend(c.to_record_batch().column("frame").to_pylist())
    for entity in ("/world/rig", "/world/target/estimate", "/world/target/truth", "/world/rig/left/model/inner"):
        assert sorted(frames[entity]) == [0, 3, 6], entity
    assert [e.frame for e in read_recording(path).estimates] == list(range(9))
    assert len(read_recording(path).truth) == 9


def test_recording_config_section(tmp_path: Path):
    from photoservo.config import load_config
    cfg = load_config(overrides=[f"recording.dir='{tmp_path}'", "recording.video='h264'"]).recording
    assert cfg.mode == "compact" and cfg.video == "h264"
    with Recorder.from_config(cfg, "move") as rec:
        rec.log_frame(0, 0.0, *frame_pair(0))
    assert rec.path.parent == tmp_path and rec.path.name.endswith("_move.rrd") and rec.path.is_file()
    assert read_recording(rec.path).setup.run["video"] == "h264"
    with pytest.raises(InputError, match="recording.video"):
        load_config(overrides=["recording.mode='preview'", "recording.video='none'"])
    with pytest.raises(InputError, match="recording.mode"):
        load_config(overrides=["recording.mode='lossless'"])


def test_a_file_cut_inside_a_message_is_read_up_to_its_last_complete_message(tmp_path: Path):
    """What a SIGKILL during a write can leave: rerun refuses such a file outright; the reader
    salvages every complete message before the cut and says where it was cut."""
    whole = tmp_path / "whole.rrd"
    with Recorder.open(whole, "track", mode="full") as rec:
        rec.log_static_setup(None, None, None, CONFIG_TOML, seed=2)
        for k in range(12):
            rec.log_frame(k, k / 30, *frame_pair(k))
            rec.flush()                                      # one message per frame, in order
    data = whole.read_bytes()
    cut = tmp_path / "cut.rrd"
    cut.write_bytes(data[: len(data) // 2 + 7])              # mid-message
    r = read_recording(cut, images=True)
    assert "cut inside a message" in r.truncated and r.setup.seed == 2
    n = len(r.images)
    assert 3 <= n < 12 and [f.index for f in r.images] == list(range(n))
    assert all(np.array_equal(f.left, frame_pair(f.index)[0]) for f in r.images)


def test_setup_logged_after_a_batch_was_written_is_the_one_read(tmp_path: Path, monkeypatch):
    """The run info is logged at open (no seed yet) and again by log_static_setup; when the
    batcher wrote the first in a chunk of its own (setup more than BATCH_S later: a loaded
    machine, a recorder process warming its kernels) the later one is read."""
    import photoservo.record.recorder as recorder

    monkeypatch.setattr(recorder, "BATCH_S", 0.05)
    path = tmp_path / "late.rrd"
    with Recorder.open(path, "track", mode="compact", video="none") as rec:
        time.sleep(0.3)
        rec.log_static_setup(None, None, None, CONFIG_TOML, seed={"tracker": 5})
        rec.log_frame(0, 0.0, *frame_pair(0))
    s = read_recording(path).setup
    assert s.seed == {"tracker": 5} and s.config_toml == CONFIG_TOML
