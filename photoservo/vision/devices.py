"""What OpenCV can open here: camera devices (by index and /dev/video* path) and video files,
each with its resolution, frame rate, FOURCC and one frame (`photoservo find-cameras`; also the
list a failed `--devices` open names).

OpenCV offers no enumeration, so devices are found by trying: indices 0..max_index-1 and the
/dev/video* nodes (a V4L2 device often has a second node for metadata that opens but delivers
no frame: it is listed with `frame = None`).
"""

from __future__ import annotations

import glob
from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class CameraInfo:
    """One source OpenCV opened. `device` as it is given to cv2.VideoCapture (an index or a
    path); width/height in px, fps as the driver reports it (0 when it does not), fourcc its
    four characters; `frame` one BGR image read from it, or None when none came."""

    device: int | str
    backend: str
    width: int
    height: int
    fps: float
    fourcc: str
    frame: np.ndarray | None

    def describe(self) -> str:
        got = "one frame read" if self.frame is not None else "opens, but delivered no frame"
        return (f"{self.device}: {self.width}x{self.height} px, {self.fps:g} fps, fourcc "
                f"{self.fourcc or '-'}, backend {self.backend}; {got}")


def _fourcc(code: float) -> str:
    c = int(code)
    text = "".join(chr((c >> (8 * i)) & 0xFF) for i in range(4))
    return text if c and text.isprintable() else ""


def probe(device: int | str) -> CameraInfo | None:
    """Open `device` (index, device path or video file), read one frame, close it. None when
    OpenCV cannot open it."""
    cap = cv2.VideoCapture(device)
    try:
        if not cap.isOpened():
            return None
        ok, frame = cap.read()
        return CameraInfo(device, cap.getBackendName(), int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)),
                          int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)), float(cap.get(cv2.CAP_PROP_FPS) or 0.0),
                          _fourcc(cap.get(cv2.CAP_PROP_FOURCC)), frame if ok else None)
    finally:
        cap.release()


def find_cameras(max_index: int = 10, extra: tuple[str, ...] = ()) -> list[CameraInfo]:
    """Every source that opens: indices 0..max_index-1, then /dev/video* nodes not already
    found by index (by their number), then `extra` (paths or video files), in that order."""
    found: list[CameraInfo] = []
    seen: set[int] = set()
    for i in range(max_index):
        info = probe(i)
        if info is not None:
            found.append(info)
            seen.add(i)
    for path in sorted(glob.glob("/dev/video*")):
        tail = path.removeprefix("/dev/video")
        if tail.isdigit() and int(tail) in seen:
            continue
        info = probe(path)
        if info is not None:
            found.append(info)
    for path in extra:
        info = probe(path)
        if info is not None:
            found.append(info)
    return found


def available_summary(max_index: int = 10) -> str:
    """One clause for an error message: which devices OpenCV can open here."""
    cams = [c for c in find_cameras(max_index) if c.frame is not None]
    if not cams:
        return "OpenCV can open no camera here (`photoservo find-cameras` lists what it tries)"
    return "OpenCV can open: " + ", ".join(f"{c.device} ({c.width}x{c.height})" for c in cams)
