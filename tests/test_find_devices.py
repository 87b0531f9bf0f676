"""`photoservo find-cameras` on a real video file (no camera on this machine) and
`photoservo find-port` against the bridge emulator's real pty."""

from __future__ import annotations

import dataclasses
import json

import cv2
import numpy as np

from photoservo.cli.main import main
from photoservo.sim.emulator import Emulator, EmulatorParams
from photoservo.tomlconf import build_dataclass, configs_dir, read_toml

EMU = build_dataclass(EmulatorParams, read_toml(configs_dir() / "default.toml")["emulator"], "emulator")


def _video(path, w=320, h=240, n=5, fps=15.0):
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h))
    assert out.isOpened()
    for i in range(n):
        img = np.full((h, w, 3), 40 * i, np.uint8)
        cv2.putText(img, str(i), (20, 120), cv2.FONT_HERSHEY_SIMPLEX, 3, (0, 0, 255), 5)
        out.write(img)
    out.release()


def test_find_cameras_lists_a_video_file_with_a_snapshot(tmp_path, capsys):
    vid = tmp_path / "left.avi"
    _video(vid)
    snaps = tmp_path / "snaps"
    rc = main(["find-cameras", str(vid), "--max-index", "2", "--snapshots", str(snaps), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0
    mine = [c for c in out if c["device"] == str(vid)]
    assert len(mine) == 1
    c = mine[0]
    assert (c["width"], c["height"]) == (320, 240) and abs(c["fps"] - 15.0) < 0.01 and c["fourcc"] == "MJPG"
    img = cv2.imread(c["snapshot"])
    assert img.shape == (240, 320, 3) and img[..., 2].max() > 200  # the first frame, red digit on black


def test_find_cameras_nothing_found_is_exit_1(tmp_path, capsys):
    rc = main(["find-cameras", str(tmp_path / "missing.avi"), "--max-index", "0", "--no-snapshots"])
    out = capsys.readouterr().out
    assert rc == 1 and "no camera" in out


def test_find_port_finds_the_emulated_bridge(capsys):
    emu = Emulator(dataclasses.replace(EMU, watchdog_periods=25))
    emu.start()
    try:
        rc = main(["find-port", emu.path, "--json"])
        ports = json.loads(capsys.readouterr().out)
    finally:
        emu.stop()
    assert rc == 0
    mine = [p for p in ports if p["device"] == emu.path]
    assert len(mine) == 1 and "7 joints" in mine[0]["bridge"], ports
    assert all(p["bridge"] is None for p in ports if p["device"] != emu.path)


def test_find_port_without_a_bridge_is_exit_1(tmp_path, capsys):
    rc = main(["find-port", "--no-probe"])
    assert rc == 0  # listing only
    rc = main(["find-port", str(tmp_path / "nothing"), "--set", "link.ack_timeout_s=0.05"])
    out = capsys.readouterr().out
    assert rc == 1 and "no bridge" in out
