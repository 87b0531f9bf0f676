"""Whole-file writes: an output is either complete or absent, never half-written. Files get the
usual mode of a new file (0666 less the umask, i.e. 0644 by default), not mkstemp's 0600."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import cv2
import numpy as np

from photoservo.errors import InputError


def _umask() -> int:
    """The process's umask: from /proc (Linux; no change to it, so safe beside other threads),
    else by setting it and putting it back."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    """Write bytes to `path` via a temp file in the same folder and a rename."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{p}: is a folder; give a file name")
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.name}.", suffix=".tmp")
    except OSError as e:
        raise InputError(f"{p}: cannot write ({e.strerror or e})") from None
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # as open() would create it
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write a text file atomically (UTF-8)."""
    write_bytes_atomic(path, text.encode("utf-8"))


def write_image_atomic(path: str | os.PathLike, image: np.ndarray) -> None:
    """Encode an image by the file's extension (.png, .jpg, ...) and write it atomically."""
    ext = Path(path).suffix or ".png"
    try:
        ok, buf = cv2.imencode(ext, image)
    except cv2.error:
        ok = False
    if not ok:
        raise InputError(f"{path}: cannot encode an image as '{ext}'")
    write_bytes_atomic(path, buf.tobytes())


def read_image(path: str | os.PathLike, what: str = "image") -> np.ndarray:
    """Read a colour image (BGR uint8). A missing, unreadable or non-image file is an InputError."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{p}: is a folder, not an image file ({what})")
    if not p.is_file():
        raise InputError(f"{p}: {what} file not found")
    data = np.fromfile(p, dtype=np.uint8)
    img = cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None
    if img is None:
        raise InputError(f"{p}: not a readable image ({what})")
    return img
