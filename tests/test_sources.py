"""Frame sources against real files: MJPG .avi videos written by cv2.VideoWriter and real
image folders in tmp dirs."""

import time

import cv2
import numpy as np
import pytest

from photoservo.errors import InputError
from photoservo.vision.sources import (
    EndOfStream,
    ImageFolderConfig,
    OpenCVPairConfig,
    SideBySideConfig,
    SourceNotConnectedError,
    VideoPairConfig,
    make_source,
    split_side_by_side,
)

W, H = 64, 48


def frame_image(i: int, side: int, width: int = W) -> np.ndarray:
    """A frame whose mean brightness encodes (frame number, side) robustly through MJPG."""
    img = np.full((H, width, 3), 20 + 8 * i + 100 * side, np.uint8)
    return img


def brightness_index(img: np.ndarray, side: int) -> int:
    return round((float(img.mean()) - 20 - 100 * side) / 8)


def write_video(path, n: int, fps: float, side: int, width: int = W, images=None) -> str:
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (width, H))
    assert vw.isOpened()
    for i in range(n):
        vw.write(images[i] if images is not None else frame_image(i, side, width))
    vw.release()
    return str(path)


def test_video_pair_delivers_all_frames_in_order_with_file_times(tmp_path):
    left = write_video(tmp_path / "l.avi", 8, 10.0, 0)
    right = write_video(tmp_path / "r.avi", 8, 10.0, 1)
    with make_source(VideoPairConfig(left, right)) as src:
        frames = list(src)
    assert [f.index for f in frames] == list(range(8))
    assert [brightness_index(f.left, 0) for f in frames] == list(range(8))
    assert [brightness_index(f.right, 1) for f in frames] == list(range(8))
    t = np.array([f.t_left for f in frames])
    assert np.allclose(np.diff(t), 0.1, atol=1e-3)  # CAP_PROP_POS_MSEC at 10 fps
    assert all(f.skew_s < 1e-6 for f in frames)
    assert abs(t[0] - time.monotonic()) < 5.0  # on the monotonic clock
    assert src.stats.delivered == 8 and src.stats.dropped_skew == 0


def test_video_pair_drops_and_counts_skewed_pairs(tmp_path):
    # Left at 10 fps, right at 8 fps: pair i has skew i*(1/8 - 1/10) = 25 ms * i.
    left = write_video(tmp_path / "l.avi", 10, 10.0, 0)
    right = write_video(tmp_path / "r.avi", 10, 8.0, 1)
    with make_source(VideoPairConfig(left, right, max_skew_s=0.060)) as src:
        frames = list(src)
    # skews 0, 25, 50 ms pass; 75 ms and more are dropped
    assert [f.index for f in frames] == [0, 1, 2]
    assert src.stats.dropped_skew == 7
    assert all(f.skew_s <= 0.060 for f in frames)


def test_video_right_offset_is_skew(tmp_path):
    left = write_video(tmp_path / "l.avi", 4, 10.0, 0)
    right = write_video(tmp_path / "r.avi", 4, 10.0, 1)
    with make_source(VideoPairConfig(left, right, right_offset_s=0.02, max_skew_s=0.01)) as src:
        assert list(src) == []
    assert src.stats.dropped_skew == 4 and src.stats.delivered == 0


def test_video_realtime_paces_reads(tmp_path):
    left = write_video(tmp_path / "l.avi", 4, 20.0, 0)
    right = write_video(tmp_path / "r.avi", 4, 20.0, 1)
    with make_source(VideoPairConfig(left, right, realtime=True)) as src:
        t0 = time.monotonic()
        frames = list(src)
        elapsed = time.monotonic() - t0
    assert len(frames) == 4
    assert elapsed >= 0.14  # frame 3 is due at 150 ms after connect
    for f in frames:  # never delivered before its time
        assert f.t_left <= time.monotonic()


def test_opencv_pair_on_video_paths_grabs_back_to_back(tmp_path):
    left = write_video(tmp_path / "l.avi", 5, 10.0, 0)
    right = write_video(tmp_path / "r.avi", 5, 10.0, 1)
    src = make_source(OpenCVPairConfig(left, right, max_skew_s=0.5))
    with pytest.raises(SourceNotConnectedError, match="call connect"):
        src.read()
    with src:
        frames = list(src)
    assert len(frames) == 5
    assert [brightness_index(f.right, 1) for f in frames] == list(range(5))
    assert all(0 <= f.t_right - f.t_left < 0.5 for f in frames)
    assert not src.is_connected


def test_opencv_pair_zero_skew_tolerance_drops_everything(tmp_path):
    # Two grabs can never share one monotonic instant: with max_skew_s=0 every pair is dropped.
    left = write_video(tmp_path / "l.avi", 3, 10.0, 0)
    right = write_video(tmp_path / "r.avi", 3, 10.0, 1)
    with make_source(OpenCVPairConfig(left, right, max_skew_s=0.0)) as src:
        assert list(src) == []
    assert src.stats.dropped_skew == 3


def test_side_by_side_splits_halves(tmp_path):
    images = [np.concatenate([frame_image(i, 0), frame_image(i, 1)], axis=1) for i in range(3)]
    path = write_video(tmp_path / "sbs.avi", 3, 10.0, 0, width=2 * W, images=images)
    with make_source(SideBySideConfig(path)) as src:
        frames = list(src)
    assert len(frames) == 3
    assert frames[0].left.shape == (H, W, 3) and frames[0].right.shape == (H, W, 3)
    assert [brightness_index(f.left, 0) for f in frames] == [0, 1, 2]
    assert [brightness_index(f.right, 1) for f in frames] == [0, 1, 2]
    assert all(f.skew_s == 0 for f in frames)


def test_split_side_by_side_odd_width():
    img = np.arange(5 * 7 * 3, dtype=np.uint8).reshape(5, 7, 3)
    left, right = split_side_by_side(img)
    assert left.shape == right.shape == (5, 3, 3)
    assert np.array_equal(right, img[:, 3:6])


def test_image_folders_pair_by_name_and_skip_unpaired(tmp_path):
    (tmp_path / "L").mkdir()
    (tmp_path / "R").mkdir()
    for i, name in enumerate(["b.png", "a.png", "c.png"]):
        cv2.imwrite(str(tmp_path / "L" / name), frame_image(i, 0))
    for i, name in enumerate(["b.png", "a.png", "d.png"]):
        cv2.imwrite(str(tmp_path / "R" / name), frame_image(i, 1))
    (tmp_path / "L" / "notes.txt").write_text("not an image")
    src = make_source(ImageFolderConfig(str(tmp_path / "L"), str(tmp_path / "R")))
    with src:
        frames = list(src)
        assert src.names == ["a.png", "b.png"]
        assert src.unpaired == ["c.png", "d.png"]
    # a.png was written as frame 1 on both sides, b.png as frame 0
    assert [brightness_index(f.left, 0) for f in frames] == [1, 0]
    assert [brightness_index(f.right, 1) for f in frames] == [1, 0]
    with src:  # reconnecting starts over
        assert src.read().index == 2  # indices keep counting across reconnects
        src.read()
        with pytest.raises(EndOfStream):
            src.read()


def test_image_folders_fps_paces(tmp_path):
    for d in ("L", "R"):
        (tmp_path / d).mkdir()
        for i in range(3):
            cv2.imwrite(str(tmp_path / d / f"{i:04d}.png"), frame_image(i, 0))
    with make_source(ImageFolderConfig(str(tmp_path / "L"), str(tmp_path / "R"), fps=20.0)) as src:
        times = [f.t_left for f in src]
    assert np.all(np.diff(times) >= 0.049)


def test_unreadable_image_is_a_failed_grab_then_timeout(tmp_path):
    for d in ("L", "R"):
        (tmp_path / d).mkdir()
    cv2.imwrite(str(tmp_path / "L" / "0.png"), frame_image(0, 0))
    (tmp_path / "R" / "0.png").write_bytes(b"not a png")
    with make_source(ImageFolderConfig(str(tmp_path / "L"), str(tmp_path / "R"), timeout_s=0.01)) as src:
        assert list(src) == []
    assert src.stats.failed_grabs == 1 and src.stats.delivered == 0


def test_missing_device_is_input_error_naming_it(tmp_path):
    src = make_source(OpenCVPairConfig(str(tmp_path / "nope0.avi"), str(tmp_path / "nope1.avi")))
    with pytest.raises(InputError, match="left: cannot open OpenCV device"):
        src.connect()
    assert not src.is_connected


@pytest.mark.parametrize(
    "build, message",
    [
        (lambda p: OpenCVPairConfig(0, 0), "left and right must be different"),
        (lambda p: OpenCVPairConfig(-1, 1), "left must be a device index"),
        (lambda p: OpenCVPairConfig(0, 1, fourcc="MJPEG"), "fourcc must be 4 characters"),
        (lambda p: OpenCVPairConfig(0, 1, exposure=-3.0), "exposure must be > 0"),
        (lambda p: OpenCVPairConfig(0, 1, white_balance_k=50.0), "white_balance_k"),
        (lambda p: OpenCVPairConfig(0, 1, max_skew_s=-1.0), "max_skew_s"),
        (lambda p: SideBySideConfig(0, width=1279), "width must be even"),
        (lambda p: SideBySideConfig(0, timeout_s=0.0), "timeout_s"),
        (lambda p: VideoPairConfig(str(p / "x.avi"), str(p / "y.avi")), "left: video file not found"),
        (lambda p: ImageFolderConfig(str(p), str(p / "none")), "right: image folder not found"),
        (lambda p: ImageFolderConfig(str(p), str(p), fps=-1.0), "fps must be >= 0"),
    ],
)
def test_config_validation_names_the_field(tmp_path, build, message):
    with pytest.raises(InputError, match=message):
        build(tmp_path)


def cameras(**kw):
    from photoservo.vision.source_config import CamerasParams

    base = {"kind": "none", "left": "", "right": "", "width": 0, "height": 0, "fps": 0.0, "fourcc": "", "exposure": 0.0,
                "white_balance_k": 0.0, "max_skew_ms": 5.0, "timeout_s": 1.0, "realtime": True}
    base.update(kw)
    return CamerasParams(**base)


def test_cameras_section_maps_to_source_configs(tmp_path):
    from photoservo.vision.source_config import source_config

    assert source_config(cameras()) is None
    c = source_config(cameras(kind="devices", left="0", right="/dev/video2", width=640, height=480,
                              fourcc="MJPG", exposure=120.0, max_skew_ms=3.0))
    assert c == OpenCVPairConfig(0, "/dev/video2", width=640, height=480, fourcc="MJPG", exposure=120.0,
                                 max_skew_s=0.003)
    sbs = source_config(cameras(kind="side_by_side", left="1", width=640, white_balance_k=4500.0))
    assert sbs == SideBySideConfig(1, width=1280, white_balance_k=4500.0)
    left = write_video(tmp_path / "l.avi", 2, 10.0, 0)
    right = write_video(tmp_path / "r.avi", 2, 10.0, 1)
    assert source_config(cameras(kind="videos", left=left, right=right, realtime=False)) == VideoPairConfig(left, right)


def test_cameras_section_errors_name_the_key(tmp_path):
    from photoservo.vision.source_config import source_config

    with pytest.raises(InputError, match="config key 'cameras.right'"):
        cameras(kind="videos", left="a.avi").validate("cameras")
    with pytest.raises(InputError, match="config key 'cameras.max_skew_ms'"):
        cameras(max_skew_ms=-1.0).validate("cameras")
    with pytest.raises(InputError, match=r"\[cameras\] \(videos\): left: video file not found"):
        source_config(cameras(kind="videos", left=str(tmp_path / "x.avi"), right=str(tmp_path / "y.avi")))


def test_refused_device_settings_are_reported_not_fatal(tmp_path):
    # A video file opened as a "device" accepts no exposure / white-balance lock: the source
    # still delivers and says which settings the device refused.
    left = write_video(tmp_path / "l.avi", 2, 10.0, 0)
    right = write_video(tmp_path / "r.avi", 2, 10.0, 1)
    cfg = OpenCVPairConfig(left, right, exposure=100.0, white_balance_k=4500.0, max_skew_s=0.5)
    with make_source(cfg) as src:
        assert len(list(src)) == 2
    assert any("left: the device refused exposure=100.0" in w for w in src.warnings)
    assert any("right: the device refused wb_temperature=4500.0" in w for w in src.warnings)


def test_latest_frame_reader_hands_out_the_newest_pair(tmp_path):
    """Cameras at 20 fps (videos paced in real time), a consumer that takes a frame every
    120 ms: it gets fresh frames, and the ones it missed are counted as overwritten."""
    from photoservo.vision.frame_reader import LatestFrameReader

    left = write_video(tmp_path / "l.avi", 12, 20.0, 0)
    right = write_video(tmp_path / "r.avi", 12, 20.0, 1)
    got = []
    with LatestFrameReader(make_source(VideoPairConfig(left, right, realtime=True))) as reader:
        while True:
            try:
                frame = reader.latest(timeout_s=1.0)
            except EndOfStream:
                break
            assert frame is not None
            got.append(frame.index)
            assert time.monotonic() - frame.t < 0.25  # fresh (a frame period is 50 ms; slack for a loaded machine)
            time.sleep(0.12)
    assert got == sorted(set(got)) and got[-1] == 11
    assert len(got) < 12 and reader.overwritten == 12 - len(got)


def test_latest_frame_reader_needs_start_and_reports_errors(tmp_path):
    from photoservo.vision.frame_reader import LatestFrameReader

    (tmp_path / "L").mkdir()
    (tmp_path / "R").mkdir()
    cv2.imwrite(str(tmp_path / "L" / "0.png"), frame_image(0, 0))
    cv2.imwrite(str(tmp_path / "R" / "0.png"), frame_image(0, 1))
    reader = LatestFrameReader(make_source(ImageFolderConfig(str(tmp_path / "L"), str(tmp_path / "R"))))
    with pytest.raises(SourceNotConnectedError, match="call start"):
        reader.latest()
    with reader:
        assert reader.latest(timeout_s=2.0).index == 0
        with pytest.raises(EndOfStream):
            reader.latest(timeout_s=2.0)
    assert not reader.source.is_connected
