"""The stereo rig: two pinhole cameras with OpenCV distortion, their extrinsics, and the
optional hand-eye transform — the rig TOML of DESIGN.md ("File contracts").

Conventions (OpenCV): camera frames are x right, y down, z forward; lengths in mm.
  X_right  = R · X_left + T          ([stereo])
  X_flange = R_he · X_left + t_he    ([hand_eye], optional)
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from photoservo.errors import InputError
from photoservo.fileio import write_text_atomic


@dataclass(frozen=True)
class Camera:
    """One pinhole camera: image size (w, h) px, intrinsics K (3x3, px), distortion
    coefficients in OpenCV order (k1 k2 p1 p2 [k3 [k4 k5 k6]])."""

    size: tuple[int, int]
    K: np.ndarray
    dist: np.ndarray

    @property
    def width(self) -> int:
        return self.size[0]

    @property
    def height(self) -> int:
        return self.size[1]


@dataclass(frozen=True)
class Rig:
    """A calibrated stereo pair. `R`, `T` map left-camera coordinates to the right camera
    (X_right = R · X_left + T, T in mm). `hand_eye` is (R, t) with X_flange = R · X_left + t."""

    left: Camera
    right: Camera
    R: np.ndarray
    T: np.ndarray
    hand_eye: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def baseline_mm(self) -> float:
        """Distance between the two optical centres (mm)."""
        return float(np.linalg.norm(self.T))

    def T_flange_left(self) -> np.ndarray | None:
        """4x4 homogeneous transform of the left camera in the flange frame, or None."""
        if self.hand_eye is None:
            return None
        T = np.eye(4)
        T[:3, :3] = self.hand_eye[0]
        T[:3, 3] = self.hand_eye[1]
        return T


def project_points(X_cam: np.ndarray, cam: Camera) -> np.ndarray:
    """Pinhole projection with OpenCV's distortion model (the same as `cv2.projectPoints`).

    X_cam: (..., 3) points in that camera's frame, mm. Returns (..., 2) pixel coordinates.
    Points with z <= 0 come back as NaN. Like OpenCV, the skew entry K[0, 1] is ignored.
    """
    X = np.asarray(X_cam, dtype=np.float64)
    z = X[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where(z > 0, X[..., 0] / z, np.nan)
        y = np.where(z > 0, X[..., 1] / z, np.nan)
    d = np.zeros(8)
    d[: min(8, cam.dist.size)] = cam.dist[:8]
    k1, k2, p1, p2, k3, k4, k5, k6 = d
    if np.any(d):
        r2 = x * x + y * y
        radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    else:
        xd, yd = x, y
    K = cam.K
    u = K[0, 0] * xd + K[0, 2]
    v = K[1, 1] * yd + K[1, 2]
    return np.stack([u, v], axis=-1)


# ----------------------------------------------------------------------------- TOML I/O


def _matrix(table: dict, key: str, shape: tuple[int, ...], where: str) -> np.ndarray:
    if key not in table:
        raise InputError(f"{where}: missing key '{key}'")
    try:
        a = np.asarray(table[key], dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{where}: key '{key}' must be numbers, got {table[key]!r}") from None
    if a.shape != shape:
        raise InputError(f"{where}: key '{key}' must have shape {list(shape)}, got {list(a.shape)}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{where}: key '{key}' has a non-finite value")
    return a


def _rotation(table: dict, key: str, where: str) -> np.ndarray:
    R = _matrix(table, key, (3, 3), where)
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or abs(np.linalg.det(R) - 1) > 1e-4:
        raise InputError(f"{where}: key '{key}' is not a rotation matrix (R·Rᵀ ≠ I or det ≠ 1)")
    return R


def _camera(doc: dict, name: str, src: str) -> Camera:
    where = f"{src} [{name}]"
    if name not in doc or not isinstance(doc[name], dict):
        raise InputError(f"{src}: missing table [{name}]")
    t = doc[name]
    unknown = set(t) - {"size", "K", "dist"}
    if unknown:
        raise InputError(f"{where}: unknown key '{sorted(unknown)[0]}'")
    size = t.get("size")
    if (
        not isinstance(size, list)
        or len(size) != 2
        or not all(isinstance(s, int) and s > 0 for s in size)
    ):
        raise InputError(f"{where}: key 'size' must be [width, height] positive integers, got {size!r}")
    K = _matrix(t, "K", (3, 3), where)
    if K[0, 0] <= 0 or K[1, 1] <= 0 or K[2, 2] != 1 or K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0:
        raise InputError(f"{where}: key 'K' must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0")
    dist = t.get("dist")
    if not isinstance(dist, list) or len(dist) not in (4, 5, 8):
        raise InputError(f"{where}: key 'dist' must list 4, 5 or 8 coefficients (k1 k2 p1 p2 [k3 [k4 k5 k6]])")
    dist_a = _matrix(t, "dist", (len(dist),), where)
    return Camera(size=(size[0], size[1]), K=K, dist=dist_a)


def parse_rig(doc: dict, src: str = "rig") -> Rig:
    """Validate a parsed rig TOML document. Errors name the file, table and key."""
    unknown = set(doc) - {"left", "right", "stereo", "hand_eye"}
    if unknown:
        raise InputError(f"{src}: unknown table [{sorted(unknown)[0]}]")
    left = _camera(doc, "left", src)
    right = _camera(doc, "right", src)
    if "stereo" not in doc or not isinstance(doc["stereo"], dict):
        raise InputError(f"{src}: missing table [stereo]")
    R = _rotation(doc["stereo"], "R", f"{src} [stereo]")
    T = _matrix(doc["stereo"], "T", (3,), f"{src} [stereo]")
    if np.linalg.norm(T) < 1e-6:
        raise InputError(f"{src} [stereo]: key 'T' is zero: the cameras need a baseline")
    hand_eye = None
    if "hand_eye" in doc:
        he = doc["hand_eye"]
        hand_eye = (_rotation(he, "R", f"{src} [hand_eye]"), _matrix(he, "t", (3,), f"{src} [hand_eye]"))
    return Rig(left=left, right=right, R=R, T=T, hand_eye=hand_eye)


def load_rig(path: str | os.PathLike) -> Rig:
    """Read and validate a rig TOML file (DESIGN.md). Raises InputError naming file and key."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as e:
        raise InputError(f"{p}: cannot read rig file ({e.strerror or e})") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{p}: not valid TOML ({e})") from None
    return parse_rig(doc, str(p))


def _fmt(a: np.ndarray) -> str:
    a = np.asarray(a, dtype=float)
    if a.ndim == 1:
        return "[" + ", ".join(repr(float(x)) for x in a) + "]"
    return "[" + ", ".join(_fmt(r) for r in a) + "]"


def dump_rig(rig: Rig) -> str:
    """The rig as TOML text in the DESIGN.md layout (round-trips through `parse_rig`)."""
    out = []
    for name, cam in (("left", rig.left), ("right", rig.right)):
        out += [
            f"[{name}]",
            f"size = [{cam.size[0]}, {cam.size[1]}]                       # width, height (px)",
            f"K = {_fmt(cam.K)}",
            f"dist = {_fmt(cam.dist)}        # k1 k2 p1 p2 k3",
            "",
        ]
    out += ["[stereo]                                # X_right = R · X_left + T, T in mm",
            f"R = {_fmt(rig.R)}", f"T = {_fmt(rig.T)}", ""]
    if rig.hand_eye is not None:
        out += ["[hand_eye]                              # X_flange = R · X_left + t, t in mm",
                f"R = {_fmt(rig.hand_eye[0])}", f"t = {_fmt(rig.hand_eye[1])}", ""]
    return "\n".join(out)


def save_rig(rig: Rig, path: str | os.PathLike) -> None:
    """Write the rig TOML atomically."""
    write_text_atomic(path, dump_rig(rig))


def default_rig(width: int = 640, height: int = 480, f_px: float = 800.0, baseline_mm: float = 100.0) -> Rig:
    """An ideal rig (no distortion, parallel cameras) as in DESIGN.md's example."""
    K = np.array([[f_px, 0.0, (width - 1) / 2], [0.0, f_px, (height - 1) / 2], [0.0, 0.0, 1.0]])
    cam = Camera(size=(width, height), K=K, dist=np.zeros(5))
    return Rig(left=cam, right=cam, R=np.eye(3), T=np.array([-baseline_mm, 0.0, 0.0]))


def horizontal_fov_deg(cam: Camera) -> float:
    """Horizontal field of view of a camera (degrees), ignoring distortion."""
    return math.degrees(2 * math.atan2(cam.width / 2, cam.K[0, 0]))
