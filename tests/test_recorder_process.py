"""The recorder in its own process (record/process.py): the same file as the in-process
Recorder given the same calls, its errors raised in the session, its bad inputs one line."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from photoservo.config import load_config
from photoservo.errors import InputError
from photoservo.record import process
from photoservo.record.files import verify_rrd
from photoservo.record.reader import read_recording
from photoservo.record.recorder import Recorder
from photoservo.record.process import RecorderProcess
from photoservo.vision.fitness import stereo_hue
from photoservo.vision.rig import default_rig, dump_rig
from test_recording import CONFIG_TOML, frame_pair, small_model

R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def _session(rec, n: int) -> None:
    """What a session logs: setup, frames with their fitness input, estimates, truth, timings,
    and the arm from another thread."""
    fit = load_config().fitness
    rec.log_static_setup(dump_rig(default_rig()), frame_pair(99)[0], small_model(), CONFIG_TOML, {"tracker": 3})

    def arm() -> None:
        for i in range(40):
            rec.log_arm(0.005 * i, np.full(7, 0.01 * i), np.full(7, 0.02 * i), np.full(7, 0.03 * i))
    th = threading.Thread(target=arm)
    th.start()
    for k in range(n):
        t = k / 30
        T = np.eye(4)
        T[:3, 3] = (k, -2.0, 600.0)
        rec.log_frame(k, t, *frame_pair(k), T_base_left=T, capture_times=(t, t + 0.001),
                      fitness_input=stereo_hue(*frame_pair(k), fit))
        rec.log_estimate(k, t, found=k % 3 != 0, fitness=0.5 + k / 100, R=R, position_mm=[1.0, 2.0, 500.0 + k],
                         alpha=2.0, size_mm=(40.0, 20.0), generations=k)
        rec.log_truth(k, t, T, (40.0, 20.0))
        rec.log_timings(t, {"ga": 10.0 + k})
    th.join()
    rec.event(n / 30, "the end")


def test_the_same_recording_as_in_process(tmp_path: Path, monkeypatch):
    """More frames than the ring has slots: the loop waits for free ones, every frame's planes
    arrive, and the file reads back as the in-process recorder's does."""
    monkeypatch.setattr(process, "RING_SLOTS", 3)
    n = 12
    a, b = tmp_path / "here.rrd", tmp_path / "there.rrd"
    with Recorder.open(a, "track", mode="compact", video="none") as rec:
        _session(rec, n)
    rec = RecorderProcess(b, "track", mode="compact", video="none")
    assert rec.path == b and not rec.written
    _session(rec, n)
    assert rec.written and rec.last_t == pytest.approx((n - 1) / 30)
    rec.close()
    rec.close()  # idempotent
    assert verify_rrd(b)[0]
    ra, rb = read_recording(a, images=True), read_recording(b, images=True)
    assert [f.index for f in rb.images] == list(range(n))
    for fa, fb in zip(ra.images, rb.images):
        assert sorted(fa.planes) == sorted(fb.planes)
        assert all(np.array_equal(fa.planes[k], fb.planes[k]) for k in fa.planes)
    assert [(e.frame, e.found, e.fitness, e.generations) for e in ra.estimates] == \
        [(e.frame, e.found, e.fitness, e.generations) for e in rb.estimates]
    assert all(np.array_equal(x.position_mm, y.position_mm) for x, y in zip(ra.estimates, rb.estimates) if x.found)
    assert np.array_equal(ra.arm["q"].values, rb.arm["q"].values)
    assert np.array_equal(ra.timings["ga"].values, rb.timings["ga"].values)
    assert np.array_equal(ra.frames[5].T_base_left, rb.frames[5].T_base_left)
    assert rb.setup.seed == {"tracker": 3} and rb.setup.config_toml == CONFIG_TOML
    assert (n / 30, "INFO", "the end") in rb.events


def test_bad_path_is_an_input_error_and_nothing_is_written(tmp_path: Path):
    (tmp_path / "taken.rrd").write_bytes(b"x")
    with pytest.raises(InputError, match="exists already"):
        RecorderProcess(tmp_path / "taken.rrd", "track")
    with pytest.raises(InputError, match="must end in .rrd"):
        RecorderProcess(tmp_path / "x.txt", "track")
    rec = RecorderProcess(tmp_path / "never.rrd", "track")
    rec.close()
    assert not rec.written and not (tmp_path / "never.rrd").exists()


def test_an_error_in_the_child_is_raised_in_the_session(tmp_path: Path):
    rec = RecorderProcess(tmp_path / "e.rrd", "track", mode="compact", video="none")
    rec.log_frame(0, 0.0, *frame_pair(0))
    rec.log_timings(0.0, {"ga": "not a number"})  # float() fails in the child
    with pytest.raises(RuntimeError, match="recording to .*e.rrd failed: ValueError"):
        for k in range(1, 200):  # raised at a later call, once the child has said so
            rec.log_frame(k, k / 30, *frame_pair(k))
    with pytest.raises(RuntimeError, match="ValueError"):
        rec.close()
    assert verify_rrd(tmp_path / "e.rrd")[0]
