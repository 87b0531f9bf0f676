"""Stereo frame sources: where the tracker's and the calibrator's image pairs come from.

One small abstract class, `StereoSource` (connect / read / disconnect, a context manager), in
the LeRobot camera style, and one config dataclass per kind of source (vision/source_config.py,
with the [cameras] section; `LatestFrameReader` hands out the newest pair: vision/frame_reader.py):

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

import time
from abc import ABC, abstractmethod
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Self

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.vision.source_config import (
    CaptureSettings,
    ImageFolderConfig,
    OpenCVPairConfig,
    SideBySideConfig,
    SourceConfig,
    VideoPairConfig,
)

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


def _apply_settings(cap: cv2.VideoCapture, cfg: CaptureSettings, what: str,
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
    "EndOfStream",
    "ImageFolderConfig",
    "ImageFolderSource",
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
    "split_side_by_side",
]
