"""Fitness distribution scans — the paper's fitness maps: the stereo fitness (method step 3) over
a slice of the 7-D search space through a given pose, one pose axis against alpha.

Position axes x, y, z move the model in the LEFT camera frame (x right, y down, z forward, mm):
t = t0 + d·e_axis. Orientation axes rx, ry, rz turn it about its own axes (degrees):
R = R0 · Rot(e_axis, d); rz is the heading (about the model normal), rx and ry tilt it. alpha
runs log-spaced over [alpha0 / k, alpha0 · k] at the fixed distance, so a column of a map is
"the same pose, a differently sized model". A sharp single peak at the given pose is what lets
the GA converge; ridges show which combinations the fitness cannot tell apart.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.geometry import axis_rotation
from photoservo.vision.fitness import FitnessParams, StereoHue, fitness
from photoservo.vision.photo_model import PhotoModel
from photoservo.vision.rig import Rig

# axis -> (unit, label of the horizontal axis)
AXES: dict[str, tuple[str, str]] = {
    "x": ("mm", "x offset, left camera (mm)"),
    "y": ("mm", "y offset, left camera (mm)"),
    "z": ("mm", "z offset (depth), left camera (mm)"),
    "rx": ("deg", "rotation about model x (deg)"),
    "ry": ("deg", "rotation about model y (deg)"),
    "rz": ("deg", "rotation about model z, heading (deg)"),
}


@dataclass(frozen=True)
class ScanSlice:
    """One fitness map: fitness[i, j] at alpha = alphas[i] and axis offset offsets[j] (in `unit`)
    from the pose (R0, t0, alpha0) it was taken around."""

    axis: str
    unit: str
    offsets: np.ndarray
    alphas: np.ndarray
    fitness: np.ndarray
    alpha0: float

    def peak(self) -> tuple[float, float, float]:
        """(offset, alpha, fitness) of the best cell."""
        i, j = np.unravel_index(int(np.argmax(self.fitness)), self.fitness.shape)
        return float(self.offsets[j]), float(self.alphas[i]), float(self.fitness[i, j])


def slice_poses(axis: str, R0: np.ndarray, t0: np.ndarray, offsets: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """The poses (R (n,3,3), t (n,3)) of one scan row: t0 moved along a left-camera axis (mm), or
    R0 turned about a model axis (deg)."""
    n = len(offsets)
    k = "xyz".index(axis[-1])
    if axis in ("x", "y", "z"):
        t = np.repeat(t0[None], n, axis=0)
        t[:, k] += offsets
        return np.repeat(R0[None], n, axis=0), t
    R = np.stack([R0 @ axis_rotation(k, np.radians(d)) for d in offsets])
    return R, np.repeat(t0[None], n, axis=0)


def scan_slice(axis: str, R0: np.ndarray, t0: np.ndarray, alpha0: float, model: PhotoModel,
               frame: StereoHue, rig: Rig, params: FitnessParams, span: float, alpha_factor: float,
               steps: int, progress: Callable[[int, int], None] | None = None) -> ScanSlice:
    """Fitness over (axis offset in [-span, span] x alpha in [alpha0/alpha_factor,
    alpha0·alpha_factor], log-spaced), `steps` x `steps` cells, one fitness call per alpha row.
    `progress(done_rows, total_rows)` is called after each row."""
    if axis not in AXES:
        raise InputError(f"scan axis '{axis}': must be one of {', '.join(AXES)}")
    offsets = np.linspace(-span, span, steps)
    alphas = alpha0 * np.geomspace(1.0 / alpha_factor, alpha_factor, steps)
    R, t = slice_poses(axis, np.asarray(R0, float), np.asarray(t0, float), offsets)
    F = np.empty((steps, steps))
    for i, a in enumerate(alphas):
        F[i] = fitness(R, t, np.full(steps, a), model, frame, rig, params)
        if progress is not None:
            progress(i + 1, steps)
    return ScanSlice(axis=axis, unit=AXES[axis][0], offsets=offsets, alphas=alphas, fitness=F,
                     alpha0=float(alpha0))


# ----------------------------------------------------------------------------- drawing

_FONT = cv2.FONT_HERSHEY_SIMPLEX
_INK = (30, 30, 30)


def _text(img: np.ndarray, s: str, org: tuple[int, int], scale: float = 0.45, align: str = "left",
          color: tuple[int, int, int] = _INK) -> None:
    (w, h), _ = cv2.getTextSize(s, _FONT, scale, 1)
    x, y = org
    if align == "center":
        x -= w // 2
    elif align == "right":
        x -= w
    cv2.putText(img, s, (int(x), int(y + h // 2)), _FONT, scale, color, 1, cv2.LINE_AA)


def _fmt(v: float) -> str:
    return f"{v:+.0f}" if abs(v) >= 10 else f"{v:+.1f}" if v != 0 else "0"


def draw_slice(s: ScanSlice, title: str, plot_w: int = 480, plot_h: int = 360) -> np.ndarray:
    """A labelled heatmap (BGR uint8): axis offset horizontally, alpha (log) vertically growing
    upwards, viridis colours with a colour bar, the peak ringed in white, the scanned-around pose
    as a magenta cross."""
    left, right, top, bottom = 90, 110, 56, 64
    img = np.full((top + plot_h + bottom, left + plot_w + right, 3), 255, np.uint8)
    F = s.fitness
    lo, hi = float(F.min()), float(F.max())
    norm = (F - lo) / (hi - lo) if hi > lo else np.zeros_like(F)
    cells = cv2.applyColorMap((norm[::-1] * 255).astype(np.uint8), cv2.COLORMAP_VIRIDIS)
    img[top:top + plot_h, left:left + plot_w] = cv2.resize(cells, (plot_w, plot_h),
                                                           interpolation=cv2.INTER_NEAREST)
    cv2.rectangle(img, (left - 1, top - 1), (left + plot_w, top + plot_h), _INK, 1)
    n_a, n_x = F.shape

    def px(j: float) -> int:  # column index -> x pixel (cell centre)
        return round(left + (j + 0.5) * plot_w / n_x)

    def py(i: float) -> int:  # alpha row index -> y pixel (row 0 at the bottom)
        return round(top + plot_h - (i + 0.5) * plot_h / n_a)

    for j in np.linspace(0, n_x - 1, 5):
        x = px(j)
        cv2.line(img, (x, top + plot_h), (x, top + plot_h + 5), _INK, 1)
        _text(img, _fmt(float(np.interp(j, np.arange(n_x), s.offsets))), (x, top + plot_h + 15), align="center")
    _text(img, AXES[s.axis][1], (left + plot_w // 2, top + plot_h + 44), 0.5, "center")
    for i in np.linspace(0, n_a - 1, 5):
        y = py(i)
        a = float(np.exp(np.interp(i, np.arange(n_a), np.log(s.alphas))))
        cv2.line(img, (left - 5, y), (left, y), _INK, 1)
        _text(img, f"{a:.3g}", (left - 8, y), align="right")
    label = np.full((24, plot_h, 3), 255, np.uint8)
    _text(label, "alpha (px/mm, log)", (plot_h // 2, 12), 0.5, "center")
    img[top:top + plot_h, 8:32] = cv2.rotate(label, cv2.ROTATE_90_COUNTERCLOCKWISE)

    # colour bar
    bx = left + plot_w + 24
    bar = cv2.applyColorMap(np.linspace(255, 0, plot_h).astype(np.uint8)[:, None], cv2.COLORMAP_VIRIDIS)
    img[top:top + plot_h, bx:bx + 16] = np.repeat(bar, 16, axis=1)
    cv2.rectangle(img, (bx - 1, top - 1), (bx + 16, top + plot_h), _INK, 1)
    for q in np.linspace(0, 1, 5):
        y = round(top + plot_h - 1 - q * (plot_h - 1))
        cv2.line(img, (bx + 16, y), (bx + 20, y), _INK, 1)
        _text(img, f"{lo + q * (hi - lo):.2f}", (bx + 23, y))
    _text(img, "fitness", (bx + 8, top + plot_h + 34), 0.45, "center")

    # the given pose and the peak
    j0 = float(np.interp(0.0, s.offsets, np.arange(n_x)))
    i0 = float(np.interp(np.log(s.alpha0), np.log(s.alphas), np.arange(n_a)))
    cv2.drawMarker(img, (px(j0), py(i0)), (255, 0, 255), cv2.MARKER_CROSS, 14, 2)
    d, a, f = s.peak()
    i, j = np.unravel_index(int(np.argmax(F)), F.shape)
    cv2.circle(img, (px(j), py(i)), 9, (255, 255, 255), 2, cv2.LINE_AA)
    cv2.circle(img, (px(j), py(i)), 11, (0, 0, 0), 1, cv2.LINE_AA)
    _text(img, title, (left, 14), 0.5)
    _text(img, f"peak F = {f:.3f} at {s.axis} {d:+.1f} {s.unit}, alpha {a:.3g} px/mm (ring); "
               "+ = given pose", (left, 36), 0.42)
    return img


# ----------------------------------------------------------------------------- pose file


def load_pose(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, float]:
    """(R, t mm, alpha px/mm) from an estimate / ground-truth JSON (DESIGN.md "Estimate").
    InputError naming the file and key when it is unreadable, not found=true or malformed."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text())
    except OSError as e:
        raise InputError(f"{p}: cannot read pose file ({e.strerror or e})") from None
    except json.JSONDecodeError as e:
        raise InputError(f"{p}: not valid JSON ({e.msg}, line {e.lineno})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{p}: expected a JSON object with position_mm, rotation, alpha_px_per_mm")
    if doc.get("found") is False:
        raise InputError(f"{p}: 'found' is false: there is no pose to scan around")

    def arr(key: str, shape: tuple[int, ...]) -> np.ndarray:
        if key not in doc or doc[key] is None:
            raise InputError(f"{p}: missing key '{key}'")
        try:
            a = np.asarray(doc[key], dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(f"{p}: key '{key}' must be numbers") from None
        if a.shape != shape or not np.all(np.isfinite(a)):
            raise InputError(f"{p}: key '{key}' must be finite numbers of shape {list(shape)}")
        return a

    t = arr("position_mm", (3,))
    R = arr("rotation", (3, 3))
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0:
        raise InputError(f"{p}: key 'rotation' is not a rotation matrix")
    alpha = float(arr("alpha_px_per_mm", ()))
    if alpha <= 0:
        raise InputError(f"{p}: key 'alpha_px_per_mm' must be > 0, got {alpha}")
    return R, t, alpha
