"""Stereo source configs (vision/sources.py): one frozen dataclass per kind of source, checked
when made, and the application's [cameras] section (`CamerasParams`) with `source_config`, which
turns it into the config of one kind.

  OpenCVPairConfig    two OpenCV devices (index or path), grabbed back to back
  SideBySideConfig    one device delivering left|right in one image
  VideoPairConfig     two video files
  ImageFolderConfig   two folders of images, paired by file name
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from photoservo.errors import InputError


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


@dataclass(frozen=True, kw_only=True)
class CaptureSettings:
    """What an OpenCV device is asked for (keyword-only in the configs below): width/height/fps 0
    and fourcc '' keep the device's defaults; `exposure` (device units) and `white_balance_k`
    (kelvin) lock those settings when given, None leaves them automatic. A pair whose two
    capture times differ by more than `max_skew_s` is dropped; `read()` gives up after
    `timeout_s`."""

    width: int = 0
    height: int = 0
    fps: float = 0.0
    fourcc: str = ""
    exposure: float | None = None
    white_balance_k: float | None = None
    max_skew_s: float = 0.005
    timeout_s: float = 1.0

    def _check_settings(self) -> None:
        _check_capture(self.width, self.height, self.fps, self.fourcc, self.exposure, self.white_balance_k)
        _check_common(self.max_skew_s, self.timeout_s)


@dataclass(frozen=True)
class OpenCVPairConfig(CaptureSettings):
    """Two OpenCV capture devices, grabbed back to back. `left`/`right`: a device index (0, 1,
    ...) or a path (/dev/video2, a video file, a GStreamer/URL string); the rest:
    `CaptureSettings`."""

    left: int | str
    right: int | str

    def __post_init__(self) -> None:
        _check_device("left", self.left)
        _check_device("right", self.right)
        if self.left == self.right:
            raise InputError(f"left and right must be different devices, both are {self.left!r}")
        self._check_settings()


@dataclass(frozen=True)
class SideBySideConfig(CaptureSettings):
    """One device whose image holds the left view in its left half and the right view in its
    right half (most USB stereo cameras). width/height are the FULL image's size (0 = default);
    the rest: `CaptureSettings`. Both halves share one capture time (skew 0)."""

    device: int | str

    def __post_init__(self) -> None:
        _check_device("device", self.device)
        if self.width % 2:
            raise InputError(f"width must be even for a side-by-side device (two halves), got {self.width}")
        self._check_settings()


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
