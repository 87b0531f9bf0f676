"""Stereo frame sources: where the tracker's and the calibrator's image pairs come from.

One small abstract class, `StereoSource` (connect / read / disconnect, a context manager), in
the LeRobot camera style, and one config dataclass per kind of source:

  OpenCVPairConfig    -> OpenCVPairSource     two OpenCV devices (index or path), grabbed back to back
  SideBySideConfig    -> SideBySideSource     one device delivering left|right in one image
  VideoPairConfig     -> VideoPairSource      two video files
  ImageFolderConfig   -> ImageFolderSource    two folders of images, paired by file name

Every `StereoFrame` carries the left and right capture times on ONE clock: `time.monotonic()`
seconds (DESIGN.md, "Time and frames in the loop"): the flange pose at those times is looked up
on the same clock. A pair whose left and right times differ by more than `max_skew_s` is
dropped and counted, never delivered. Timeouts, failed grabs and dropped pairs are reported in
`source.stats` (a `SourceStats`), not raised: a live loop keeps running over a bad frame.
"""

from __future__ import annotations

import os
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Self

import cv2
import numpy as np

from photoservo.errors import InputError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm")


class SourceNotConnectedError(ConnectionError):
    """`read()` on a source that is not connected: call `connect()` first."""


class EndOfStream(Exception):
    """A finite source (video files, image folders) has no more pairs."""


@dataclass(frozen=True)
class StereoFrame:
    """One stereo pair. Images are BGR uint8 (h, w, 3). `t_left`, `t_right` are capture times in
    `time.monotonic()` seconds. `index` counts the pairs the source captured (starting at 0),
    dropped ones included: a gap in the indices is a dropped pair."""

    index: int
    left: np.ndarray
    right: np.ndarray
    t_left: float
    t_right: float

    @property
    def skew_s(self) -> float:
        """|t_left - t_right| (s)."""
        return abs(self.t_left - self.t_right)

    @property
    def t(self) -> float:
        """The pair's capture time: the mean of the left and right times (monotonic s)."""
        return 0.5 * (self.t_left + self.t_right)


@dataclass
class SourceStats:
    """Counters a source keeps while it runs (reported, not fatal).

    delivered: pairs returned by `read()`; dropped_skew: pairs dropped because their left/right
    times differed by more than `max_skew_s`; failed_grabs: grabs or decodes that failed;
    timeouts: `read()` calls that returned None because no good pair came within `timeout_s`."""

    delivered: int = 0
    dropped_skew: int = 0
    failed_grabs: int = 0
    timeouts: int = 0

    def summary(self) -> str:
        return (f"{self.delivered} pairs delivered, {self.dropped_skew} dropped for skew, "
                f"{self.failed_grabs} failed grabs, {self.timeouts} timeouts")


def _check_common(max_skew_s: float, timeout_s: float) -> None:
    if not (max_skew_s >= 0):
        raise InputError(f"max_skew_s must be >= 0 s, got {max_skew_s!r}")
    if not (timeout_s > 0):
        raise InputError(f"timeout_s must be > 0 s, got {timeout_s!r}")


def _check_capture(width: int, height: int, fps: float, fourcc: str, exposure: float | None,
                   white_balance_k: float | None) -> None:
    if width < 0 or height < 0:
        raise InputError(f"width/height must be >= 0 px (0 = device default), got {width}x{height}")
    if fps < 0:
        raise InputError(f"fps must be >= 0 (0 = device default), got {fps!r}")
    if fourcc and len(fourcc) != 4:
        raise InputError(f"fourcc must be 4 characters (e.g. 'MJPG') or empty, got {fourcc!r}")
    if exposure is not None and exposure <= 0:
        raise InputError(f"exposure must be > 0 (device units) or None for auto, got {exposure!r}")
    if white_balance_k is not None and not (1000 <= white_balance_k <= 15000):
        raise InputError(f"white_balance_k must be in 1000..15000 K or None for auto, got {white_balance_k!r}")


def _check_device(name: str, device: int | str) -> None:
    if isinstance(device, bool) or not isinstance(device, (int, str)):
        raise InputError(f"{name} must be a device index or a path, got {device!r}")
    if isinstance(device, int) and device < 0:
        raise InputError(f"{name} must be a device index >= 0 or a path, got {device!r}")
    if isinstance(device, str) and not device:
        raise InputError(f"{name} must not be empty")


# ----------------------------------------------------------------------------- configs


@dataclass(frozen=True)
class OpenCVPairConfig:
    """Two OpenCV capture devices. `left`/`right`: a device index (0, 1, ...) or a path
    (/dev/video2, a video file, a GStreamer/URL string). width/height/fps 0 and fourcc ''
    keep the device's defaults; `exposure` (device units) and `white_balance_k` (kelvin) lock
    those settings when given, None leaves them automatic. A pair whose two grab times differ by
    more than `max_skew_s` is dropped; `read()` gives up after `timeout_s`."""

    left: int | str
    right: int | str
    width: int = 0
    height: int = 0
    fps: float = 0.0
    fourcc: str = ""
    exposure: float | None = None
    white_balance_k: float | None = None
    max_skew_s: float = 0.005
    timeout_s: float = 1.0

    def __post_init__(self) -> None:
        _check_device("left", self.left)
        _check_device("right", self.right)
        if self.left == self.right:
            raise InputError(f"left and right must be different devices, both are {self.left!r}")
        _check_capture(self.width, self.height, self.fps, self.fourcc, self.exposure, self.white_balance_k)
        _check_common(self.max_skew_s, self.timeout_s)


@dataclass(frozen=True)
class SideBySideConfig:
    """One device whose image holds the left view in its left half and the right view in its
    right half (most USB stereo cameras). width/height are the FULL image's size (0 = default);
    the other fields as in `OpenCVPairConfig`. Both halves share one capture time (skew 0)."""

    device: int | str
    width: int = 0
    height: int = 0
    fps: float = 0.0
    fourcc: str = ""
    exposure: float | None = None
    white_balance_k: float | None = None
    max_skew_s: float = 0.005
    timeout_s: float = 1.0

    def __post_init__(self) -> None:
        _check_device("device", self.device)
        if self.width % 2:
            raise InputError(f"width must be even for a side-by-side device (two halves), got {self.width}")
        _check_capture(self.width, self.height, self.fps, self.fourcc, self.exposure, self.white_balance_k)
        _check_common(self.max_skew_s, self.timeout_s)


@dataclass(frozen=True)
class VideoPairConfig:
    """Two video files, read frame by frame in step. Each frame's time is its position in its
    file (CAP_PROP_POS_MSEC) mapped onto the monotonic clock: t = t0 + pos_ms / 1000, with t0
    the monotonic time of `connect()`. So two files recorded with different frame rates or a
    start offset (`right_offset_s`, added to the right file's times) show up as skew.
    `realtime=True` paces `read()` so that no frame is delivered before its time; False reads
    as fast as the caller asks (the times are still the files' times)."""

    left: str
    right: str
    realtime: bool = False
    right_offset_s: float = 0.0
    max_skew_s: float = 0.005
    timeout_s: float = 1.0

    def __post_init__(self) -> None:
        for name in ("left", "right"):
            p = getattr(self, name)
            if not isinstance(p, (str, os.PathLike)) or not Path(p).is_file():
                raise InputError(f"{name}: video file not found: {p!r}")
        _check_common(self.max_skew_s, self.timeout_s)


@dataclass(frozen=True)
class ImageFolderConfig:
    """Two folders of images (.png, .jpg, ...), sorted by name and paired by file name: a name
    present in only one folder is skipped (counted in `unpaired`). Both images of a pair are
    stamped with one monotonic time as they are read (skew 0). `fps` > 0 paces `read()` at that
    rate; 0 reads as fast as asked."""

    left: str
    right: str
    fps: float = 0.0
    max_skew_s: float = 0.005
    timeout_s: float = 1.0

    def __post_init__(self) -> None:
        for name in ("left", "right"):
            p = getattr(self, name)
            if not isinstance(p, (str, os.PathLike)) or not Path(p).is_dir():
                raise InputError(f"{name}: image folder not found: {p!r}")
        if self.fps < 0:
            raise InputError(f"fps must be >= 0 (0 = unpaced), got {self.fps!r}")
        _check_common(self.max_skew_s, self.timeout_s)


SourceConfig = OpenCVPairConfig | SideBySideConfig | VideoPairConfig | ImageFolderConfig


@dataclass(frozen=True)
class CamerasParams:
    """[cameras] config section: the stereo source `track` and `calibrate capture` use
    (configs/default.toml documents each key). `source_config()` turns it into the config of
    one source kind, where the per-kind checks run."""

    kind: Literal["none", "devices", "side_by_side", "videos", "folders"]
    left: str  # device index ("0"), device path, video file or image folder
    right: str  # the same for the right camera ("" for side_by_side)
    width: int  # px per camera; 0 = device default
    height: int  # px; 0 = device default
    fps: float  # devices: requested rate; folders: pacing; 0 = default / unpaced
    fourcc: str  # e.g. "MJPG"; "" = device default
    exposure: float  # device units; 0 = automatic
    white_balance_k: float  # kelvin; 0 = automatic
    max_skew_ms: float  # pairs whose left/right capture times differ more are dropped
    timeout_s: float  # a read that gets no good pair for this long returns None (counted)
    realtime: bool  # videos: deliver frames at their file times (false: as fast as read)

    def validate(self, where: str) -> None:
        w = f"{where}." if where else ""
        if self.kind != "none" and not self.left:
            raise InputError(f"config key '{w}left': must name a device, file or folder for kind '{self.kind}'")
        if self.kind in ("devices", "videos", "folders") and not self.right:
            raise InputError(f"config key '{w}right': must name a device, file or folder for kind '{self.kind}'")
        for k in ("width", "height", "fps", "exposure", "white_balance_k", "max_skew_ms"):
            if getattr(self, k) < 0:
                raise InputError(f"config key '{w}{k}': must be >= 0, got {getattr(self, k)}")
        if self.timeout_s <= 0:
            raise InputError(f"config key '{w}timeout_s': must be > 0, got {self.timeout_s}")


def _device(text: str) -> int | str:
    return int(text) if text.isdigit() else text


def source_config(p: CamerasParams) -> SourceConfig | None:
    """The source config for a [cameras] section; None for kind 'none'.

    Raises:
        InputError: a per-kind check failed (the message names the field).
    """
    skew, lock = p.max_skew_ms / 1000.0, {
        "fps": p.fps, "fourcc": p.fourcc, "exposure": p.exposure or None,
        "white_balance_k": p.white_balance_k or None}
    try:
        if p.kind == "devices":
            return OpenCVPairConfig(_device(p.left), _device(p.right), width=p.width, height=p.height,
                                    max_skew_s=skew, timeout_s=p.timeout_s, **lock)
        if p.kind == "side_by_side":
            return SideBySideConfig(_device(p.left), width=2 * p.width, height=p.height, max_skew_s=skew,
                                    timeout_s=p.timeout_s, **lock)
        if p.kind == "videos":
            return VideoPairConfig(p.left, p.right, realtime=p.realtime, max_skew_s=skew, timeout_s=p.timeout_s)
        if p.kind == "folders":
            return ImageFolderConfig(p.left, p.right, fps=p.fps, max_skew_s=skew, timeout_s=p.timeout_s)
    except InputError as e:
        raise InputError(f"[cameras] ({p.kind}): {e}") from None
    return None


# ----------------------------------------------------------------------------- the interface


class StereoSource(ABC):
    """A source of stereo pairs stamped on the monotonic clock.

    Use as a context manager (`with make_source(cfg) as src: frame = src.read()`), or call
    `connect()` / `disconnect()` yourself. Iterating yields pairs until a finite source ends.
    """

    def __init__(self, config: SourceConfig) -> None:
        self.config = config
        self.stats = SourceStats()
        self.warnings: list[str] = []  # settings a device refused (e.g. exposure lock)
        self._captured = 0

    # -- device-specific parts
    @property
    @abstractmethod
    def is_connected(self) -> bool:
        """True between a successful `connect()` and `disconnect()`."""

    @abstractmethod
    def connect(self) -> None:
        """Open the devices or files.

        Raises:
            InputError: a device or file cannot be opened (the message names it).
        """

    @abstractmethod
    def disconnect(self) -> None:
        """Release the devices or files. Safe to call twice."""

    @abstractmethod
    def _grab_pair(self) -> tuple[np.ndarray, np.ndarray, float, float] | None:
        """Capture one pair: (left, right, t_left, t_right), or None when the grab failed.

        Raises:
            EndOfStream: a finite source has no more pairs.
        """

    # -- shared logic
    def read(self) -> StereoFrame | None:
        """The next pair whose left/right skew is within `max_skew_s`.

        Returns:
            A StereoFrame, or None when no good pair came within `timeout_s` (counted in
            `stats.timeouts`; pairs dropped for skew and failed grabs are counted too).

        Raises:
            SourceNotConnectedError: `connect()` was not called.
            EndOfStream: a finite source (files, folders) is exhausted.
        """
        if not self.is_connected:
            raise SourceNotConnectedError(f"{type(self).__name__} is not connected: call connect() first")
        deadline = time.monotonic() + self.config.timeout_s
        while True:
            pair = self._grab_pair()
            if pair is None:
                self.stats.failed_grabs += 1
            else:
                left, right, t_left, t_right = pair
                index = self._captured
                self._captured += 1
                if abs(t_left - t_right) > self.config.max_skew_s:
                    self.stats.dropped_skew += 1
                else:
                    self.stats.delivered += 1
                    return StereoFrame(index=index, left=left, right=right, t_left=t_left, t_right=t_right)
            if time.monotonic() >= deadline:
                self.stats.timeouts += 1
                return None

    def __iter__(self) -> Iterator[StereoFrame]:
        """Good pairs until the source ends (None results from timeouts are skipped)."""
        while True:
            try:
                frame = self.read()
            except EndOfStream:
                return
            if frame is not None:
                yield frame

    def __enter__(self) -> Self:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.disconnect()


# ----------------------------------------------------------------------------- OpenCV devices


def _open_capture(device: int | str, what: str) -> cv2.VideoCapture:
    cap = cv2.VideoCapture(device)
    if not cap.isOpened():
        cap.release()
        from photoservo.vision.devices import available_summary

        raise InputError(f"{what}: cannot open OpenCV device {device!r}; {available_summary()}")
    return cap


def _apply_settings(cap: cv2.VideoCapture, cfg: OpenCVPairConfig | SideBySideConfig, what: str,
                    warnings: list[str]) -> None:
    """Set FOURCC, size, fps, and lock exposure / white balance when asked. A setting the device
    refuses is recorded in `warnings` (many drivers ignore some), not fatal."""
    def put(prop: int, value: float, name: str) -> None:
        if not cap.set(prop, value):
            warnings.append(f"{what}: the device refused {name}={value}")

    if cfg.fourcc:
        put(cv2.CAP_PROP_FOURCC, cv2.VideoWriter_fourcc(*cfg.fourcc), f"fourcc {cfg.fourcc}")
    if cfg.width:
        put(cv2.CAP_PROP_FRAME_WIDTH, cfg.width, "width")
    if cfg.height:
        put(cv2.CAP_PROP_FRAME_HEIGHT, cfg.height, "height")
    if cfg.fps:
        put(cv2.CAP_PROP_FPS, cfg.fps, "fps")
    if cfg.exposure is not None:
        put(cv2.CAP_PROP_AUTO_EXPOSURE, 1, "auto_exposure (1 = manual on V4L2)")
        put(cv2.CAP_PROP_EXPOSURE, cfg.exposure, "exposure")
    if cfg.white_balance_k is not None:
        put(cv2.CAP_PROP_AUTO_WB, 0, "auto_wb")
        put(cv2.CAP_PROP_WB_TEMPERATURE, cfg.white_balance_k, "wb_temperature")


class OpenCVPairSource(StereoSource):
    """Two OpenCV devices. Both are latched with `grab()` back to back (the two calls are what
    sets the skew), then decoded with `retrieve()`; each side's time is the monotonic time its
    `grab()` returned."""

    config: OpenCVPairConfig

    def __init__(self, config: OpenCVPairConfig) -> None:
        super().__init__(config)
        self._caps: tuple[cv2.VideoCapture, cv2.VideoCapture] | None = None

    @property
    def is_connected(self) -> bool:
        return self._caps is not None

    def connect(self) -> None:
        if self._caps is not None:
            return
        left = _open_capture(self.config.left, "left")
        try:
            right = _open_capture(self.config.right, "right")
        except InputError:
            left.release()
            raise
        for cap, what in ((left, "left"), (right, "right")):
            _apply_settings(cap, self.config, what, self.warnings)
        self._caps = (left, right)

    def disconnect(self) -> None:
        if self._caps is not None:
            for cap in self._caps:
                cap.release()
            self._caps = None

    def _grab_pair(self) -> tuple[np.ndarray, np.ndarray, float, float] | None:
        assert self._caps is not None
        left, right = self._caps
        ok_l = left.grab()
        t_left = time.monotonic()
        ok_r = right.grab()
        t_right = time.monotonic()
        if not ok_l and not ok_r and _at_end(left) and _at_end(right):
            raise EndOfStream
        if not (ok_l and ok_r):
            return None
        ok_l, img_l = left.retrieve()
        ok_r, img_r = right.retrieve()
        if not (ok_l and ok_r):
            return None
        return img_l, img_r, t_left, t_right


def _at_end(cap: cv2.VideoCapture) -> bool:
    """True for a file-backed capture that has read all its frames (a live device has no count)."""
    n = cap.get(cv2.CAP_PROP_FRAME_COUNT)
    return n > 0 and cap.get(cv2.CAP_PROP_POS_FRAMES) >= n


class SideBySideSource(StereoSource):
    """One device with left|right halves; both halves share the grab's monotonic time."""

    config: SideBySideConfig

    def __init__(self, config: SideBySideConfig) -> None:
        super().__init__(config)
        self._cap: cv2.VideoCapture | None = None

    @property
    def is_connected(self) -> bool:
        return self._cap is not None

    def connect(self) -> None:
        if self._cap is None:
            cap = _open_capture(self.config.device, "device")
            _apply_settings(cap, self.config, "device", self.warnings)
            self._cap = cap

    def disconnect(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None

    def _grab_pair(self) -> tuple[np.ndarray, np.ndarray, float, float] | None:
        assert self._cap is not None
        ok = self._cap.grab()
        t = time.monotonic()
        if not ok:
            if _at_end(self._cap):
                raise EndOfStream
            return None
        ok, img = self._cap.retrieve()
        if not ok or img is None:
            return None
        left, right = split_side_by_side(img)
        return left, right, t, t


def split_side_by_side(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split a side-by-side stereo image into (left, right) halves (copies, contiguous).
    An odd width drops the last column."""
    half = image.shape[1] // 2
    return np.ascontiguousarray(image[:, :half]), np.ascontiguousarray(image[:, half : 2 * half])


# ----------------------------------------------------------------------------- files


class VideoPairSource(StereoSource):
    """Two video files read in step; times from CAP_PROP_POS_MSEC (see `VideoPairConfig`)."""

    config: VideoPairConfig

    def __init__(self, config: VideoPairConfig) -> None:
        super().__init__(config)
        self._caps: tuple[cv2.VideoCapture, cv2.VideoCapture] | None = None
        self._t0 = 0.0

    @property
    def is_connected(self) -> bool:
        return self._caps is not None

    def connect(self) -> None:
        if self._caps is not None:
            return
        caps = []
        for name in ("left", "right"):
            path = getattr(self.config, name)
            cap = cv2.VideoCapture(str(path))
            if not cap.isOpened():
                for c in caps:
                    c.release()
                cap.release()
                raise InputError(f"{path}: cannot open video file ({name})")
            caps.append(cap)
        self._caps = (caps[0], caps[1])
        self._t0 = time.monotonic()

    def disconnect(self) -> None:
        if self._caps is not None:
            for cap in self._caps:
                cap.release()
            self._caps = None

    def _grab_pair(self) -> tuple[np.ndarray, np.ndarray, float, float] | None:
        assert self._caps is not None
        frames, times = [], []
        for cap, offset in zip(self._caps, (0.0, self.config.right_offset_s)):
            ok, img = cap.read()
            if not ok or img is None:
                raise EndOfStream
            # after read(), POS_MSEC is the presentation time of the frame just decoded
            pos_ms = cap.get(cv2.CAP_PROP_POS_MSEC)
            frames.append(img)
            times.append(self._t0 + pos_ms / 1000.0 + offset)
        if self.config.realtime:
            wait = max(times) - time.monotonic()
            if wait > 0:
                time.sleep(wait)
        return frames[0], frames[1], times[0], times[1]


def _image_names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)


class ImageFolderSource(StereoSource):
    """Two image folders paired by file name (see `ImageFolderConfig`). `names` lists the paired
    names in reading order; `unpaired` the names found in one folder only."""

    config: ImageFolderConfig

    def __init__(self, config: ImageFolderConfig) -> None:
        super().__init__(config)
        self.names: list[str] = []
        self.unpaired: list[str] = []
        self._next = 0
        self._connected = False
        self._t_last = -float("inf")

    @property
    def is_connected(self) -> bool:
        return self._connected

    def connect(self) -> None:
        left = _image_names(Path(self.config.left))
        right = set(_image_names(Path(self.config.right)))
        self.names = [n for n in left if n in right]
        self.unpaired = sorted(set(left).symmetric_difference(right))
        if not self.names:
            raise InputError(f"{self.config.left} and {self.config.right}: no image name is in both folders")
        self._next = 0
        self._connected = True

    def disconnect(self) -> None:
        self._connected = False

    @property
    def current_name(self) -> str | None:
        """File name of the pair most recently read (None before the first)."""
        return self.names[self._next - 1] if self._next > 0 else None

    def _grab_pair(self) -> tuple[np.ndarray, np.ndarray, float, float] | None:
        if self._next >= len(self.names):
            raise EndOfStream
        name = self.names[self._next]
        self._next += 1
        if self.config.fps > 0:
            wait = self._t_last + 1.0 / self.config.fps - time.monotonic()
            if wait > 0:
                time.sleep(wait)
        left = cv2.imread(str(Path(self.config.left) / name), cv2.IMREAD_COLOR)
        right = cv2.imread(str(Path(self.config.right) / name), cv2.IMREAD_COLOR)
        t = time.monotonic()
        self._t_last = t
        if left is None or right is None:
            return None
        return left, right, t, t


class LatestFrameReader:
    """Reads a source on a background thread and hands out only the newest pair: a loop that
    is slower than the cameras gets fresh frames instead of a growing backlog (LeRobot's
    `async_read`). Pairs replaced before anyone took them are counted in `overwritten`.

        with LatestFrameReader(make_source(cfg)) as reader:
            frame = reader.latest(timeout_s=0.1)   # None on timeout (counted in source.stats)

    The source is connected and disconnected by the reader. Errors in the thread (other than
    the end of a finite source) are raised again by the next `latest()`.
    """

    def __init__(self, source: StereoSource) -> None:
        self.source = source
        self.overwritten = 0
        self._cond = threading.Condition()
        self._frame: StereoFrame | None = None
        self._ended = False
        self._error: BaseException | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Connect the source and start reading.

        Raises:
            InputError: the source cannot be opened.
        """
        self.source.connect()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="stereo-reader", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread and disconnect the source. Safe to call twice."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=max(2.0, 2 * self.source.config.timeout_s))
            self._thread = None
        self.source.disconnect()

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                frame = self.source.read()
                if frame is None:
                    continue
                with self._cond:
                    if self._frame is not None:
                        self.overwritten += 1
                    self._frame = frame
                    self._cond.notify_all()
        except EndOfStream:
            pass
        except Exception as e:  # noqa: BLE001 - handed to the consumer by latest()
            self._error = e
        with self._cond:
            self._ended = True
            self._cond.notify_all()

    def latest(self, timeout_s: float | None = None) -> StereoFrame | None:
        """The newest pair not yet returned, waiting up to `timeout_s` (None: the source's
        timeout_s) for one. Returns None on timeout.

        Raises:
            EndOfStream: a finite source ended and its last pair was taken.
            SourceNotConnectedError: `start()` was not called.
        """
        if self._thread is None:
            raise SourceNotConnectedError("LatestFrameReader is not started: call start() first")
        wait = self.source.config.timeout_s if timeout_s is None else timeout_s
        with self._cond:
            self._cond.wait_for(lambda: self._frame is not None or self._ended, timeout=wait)
            frame, self._frame = self._frame, None
            if frame is None:
                if self._error is not None:
                    raise self._error
                if self._ended:
                    raise EndOfStream
                self.source.stats.timeouts += 1
            return frame

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def make_source(config: SourceConfig) -> StereoSource:
    """The source for a config (not yet connected)."""
    kinds: dict[type, type[StereoSource]] = {
        OpenCVPairConfig: OpenCVPairSource,
        SideBySideConfig: SideBySideSource,
        VideoPairConfig: VideoPairSource,
        ImageFolderConfig: ImageFolderSource,
    }
    try:
        return kinds[type(config)](config)
    except KeyError:
        raise InputError(f"unknown source config {type(config).__name__}") from None


__all__ = [
    "CamerasParams",
    "EndOfStream",
    "ImageFolderConfig",
    "ImageFolderSource",
    "LatestFrameReader",
    "OpenCVPairConfig",
    "OpenCVPairSource",
    "SideBySideConfig",
    "SideBySideSource",
    "SourceConfig",
    "SourceNotConnectedError",
    "SourceStats",
    "StereoFrame",
    "StereoSource",
    "VideoPairConfig",
    "VideoPairSource",
    "make_source",
    "source_config",
    "split_side_by_side",
]
