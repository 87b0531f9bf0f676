"""What the viewer draws from a session's numbers (issues 6 and 13), for `record.recorder`:
the rig's cameras, the photo-model, pose boxes, the arm and its flange path, and the time series
(plots/, timing/, arm/ in degrees), queued and written as column chunks.

Cost: a rerun log call costs ~0.1-0.2 ms of Python, a column chunk about the same for any
number of rows, so series are queued and written every SERIES_FLUSH_S of frames (the live view
lags by that much), every ARM_BATCH samples when no frames come (`move`), and at close; the
arm (forward kinematics of the latest q) is redrawn at most every ARM_DRAW_PERIOD_S.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import cv2
import numpy as np

from photoservo.record import layout as L
from photoservo.record.layout import rr
from photoservo.robot.pa10 import fk_frames

PATH_S = 10.0          # seconds of flange path kept in `world/flange/path`
PATH_PERIOD_S = 0.5    # how often the path strip is re-logged
SERIES_FLUSH_S = 0.5   # queued time series (plots, timings, arm) are written this often
ARM_BATCH = 750        # ...or, when no frames come (move), at this many queued samples
ARM_DRAW_PERIOD_S = 0.1   # the arm is redrawn at most this often
DRAW_POINTS = 150      # projected inner (and outer) points drawn per camera and frame, at most


def transform(T: np.ndarray) -> Any:
    """A pose T_parent_child (4x4, mm) as a rerun transform (child in parent)."""
    T = np.asarray(T, dtype=np.float64)
    return rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3])


def pack_model(model: Any) -> bytes:
    """A dataclass of arrays / numbers / tuples (the PhotoModel) as npz bytes (bit-exact)."""
    import dataclasses
    import io
    arrays = {f.name: np.asarray(getattr(model, f.name)) for f in dataclasses.fields(model)}
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


class Drawing:
    """The recorder's drawn and plotted part; logs through the recorder (`_log`, `_log_static`,
    its lock and stream). `queue_scalar` and `queue_arm` only queue (no rerun call, no lock),
    so a control thread may call them."""

    def __init__(self, rec: Any, rate_hz: float = 0.0) -> None:
        self.rec = rec
        self.rate_hz = rate_hz                # per-frame drawings at most this often (0 = every frame)
        self.drawn: tuple[int, int] = (-1, -1)   # (1/rate_hz slot, frame) drawn last
        self.series: deque[tuple] = deque()   # (entity, t, frame, values) not yet written
        self.flushed_t = -math.inf
        self.arm_last: tuple[float, np.ndarray] | None = None
        self.arm_drawn_t = -math.inf
        self.path_pts: deque[tuple[float, np.ndarray]] = deque()
        self.path_last_t = -math.inf
        self.model_: Any = None   # the photo-model and rig of the setup (`model`, `rig`)
        self.rig_: Any = None

    # --- static ----------------------------------------------------------------------------

    def rig(self, rig: Any) -> None:
        """Both cameras' Pinholes (RDF) and the right camera's place: X_right = R X_left + T."""
        self.rig_ = rig  # projects the estimates' model points (`projection`)
        for side, cam in (("left", rig.left), ("right", rig.right)):
            self.rec._log_static(L.E_CAM[side], rr.Pinhole(
                image_from_camera=cam.K, resolution=list(cam.size), camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=100.0))
        self.rec._log_static(L.E_CAM["right"], rr.Transform3D(
            translation=rig.T, mat3x3=rig.R, relation=rr.TransformRelation.ChildFromParent))

    def photo(self, photo_bgr: np.ndarray) -> None:
        ok, buf = cv2.imencode(".png", photo_bgr)
        if not ok:
            raise ValueError("cannot encode the photo as PNG")
        self.rec._log_static(L.E_PHOTO, rr.EncodedImage(contents=buf.tobytes(), media_type="image/png"))

    def model(self, model: Any) -> None:
        """The PhotoModel's arrays (bit-exact npz) and its points drawn on the photo."""
        self.model_ = model  # projected at the estimates' poses (`projection`)
        self.rec._log_static(L.E_MODEL, rr.AnyValues(npz=L.blob(pack_model(model)), type=type(model).__name__))
        o = np.asarray(model.origin_px, dtype=np.float64)
        self.rec._log_static(f"{L.E_PHOTO}/inner", rr.Points2D(np.asarray(model.inner_uv) + o,
                                                                colors=[0, 255, 0], radii=1.0))
        self.rec._log_static(f"{L.E_PHOTO}/outer", rr.Points2D(np.asarray(model.outer_uv) + o,
                                                                colors=[255, 0, 255], radii=1.0))

    # --- per frame -------------------------------------------------------------------------

    def due(self, frame: int, t: float) -> bool:
        """Whether frame `frame` at loop time t (s) gets its pictures (the rig's pose, the pose
        boxes, the projected points): every frame when rate_hz is 0, else the first frame of
        each 1/rate_hz slot, like the watch-only video they are drawn over (its frames and these
        pictures then match; the numbers, in data/ and plots/, are logged every frame)."""
        if self.rate_hz <= 0 or frame == self.drawn[1]:
            return True
        slot = math.floor(t * self.rate_hz)
        if slot <= self.drawn[0]:
            return False
        self.drawn = (slot, frame)
        return True

    def box(self, entity: str, t: float, frame: int | None, T: np.ndarray, size_mm: Any,
            color: list[int]) -> None:
        """A pose (T_base_model) with axes and, if the size is known, the flat model box
        (drawn in the model frame: the entity's own transform applies to it); a frame's only
        when `due`."""
        if frame is not None and not self.due(frame, t):
            return
        parts = [transform(T), rr.TransformAxes3D(axis_length=30.0)]
        if size_mm is not None:
            w, h = (float(s) for s in size_mm)
            parts.append(rr.Boxes3D(half_sizes=[[w / 2, h / 2, 1.0]], colors=[color]))
        self.rec._log(entity, t, frame, *parts)

    def projection(self, t: float, frame: int, found: bool, projection: Any,
                   pose: tuple[np.ndarray, np.ndarray, float] | None = None) -> None:
        """The best model's projected points on each image, inner and outer (colours and radii
        static, per frame the positions only), at most DRAW_POINTS of each (evenly strided: a
        picture of the pose, whose exact numbers are in data/estimate); cleared when not found;
        only when `due`. Without a `projection`, the points are projected here from `pose` (R,
        position_mm in the left camera, alpha) with the recorded photo-model and rig: only the
        frames drawn pay for it, and not the session's loop."""
        if not self.due(frame, t):
            return
        if projection is None and found and pose is not None and self.model_ is not None and self.rig_ is not None:
            from photoservo.vision.fitness import project_model
            R, position_mm, alpha = pose
            projection = project_model(R[None], position_mm[None], np.array([alpha]), self.model_, self.rig_)
        for side in L.SIDES:
            if not (found and projection is not None):
                self.rec._log(L.E_POINTS[side], t, frame, rr.Clear(recursive=True))
                continue
            for kind in ("inner", "outer"):
                uv = np.asarray(getattr(projection, f"{kind}_{side}"), dtype=np.float64).reshape(-1, 2)
                uv = uv[:: max(1, -(-len(uv) // DRAW_POINTS))]
                self.rec._log(f"{L.E_POINTS[side]}/{kind}", t, frame,
                              rr.Points2D.from_fields(positions=uv[np.isfinite(uv).all(axis=1)]))

    def point_styles(self) -> None:
        """Inner points green, outer magenta (static: not repeated per frame)."""
        for side in L.SIDES:
            for kind, color in (("inner", [0, 255, 0]), ("outer", [255, 0, 255])):
                self.rec._log_static(f"{L.E_POINTS[side]}/{kind}", rr.Points2D.from_fields(
                    colors=[color], radii=[1.5]))

    def tick(self, t: float) -> None:
        """At each frame: write the queued series every SERIES_FLUSH_S, redraw the arm."""
        if t - self.flushed_t >= SERIES_FLUSH_S:
            self.flush(t)
        if self.arm_last is not None and t - self.arm_drawn_t >= ARM_DRAW_PERIOD_S:
            self.arm(*self.arm_last)

    # --- series ----------------------------------------------------------------------------

    def queue_scalar(self, entity: str, t: float, frame: int | None, value: float) -> None:
        self.series.append((entity, float(t), frame, np.array([value])))

    def queue_arm(self, t: float, q: np.ndarray, setpoint: np.ndarray | None,
                  command: np.ndarray | None, last_frame_t: float) -> None:
        """Joint state, setpoint (rad) and velocity command (rad/s), queued in degrees."""
        for entity, v in zip(L.E_ARM, (q, setpoint, command)):
            if v is not None:
                self.series.append((entity, float(t), None, np.degrees(np.asarray(v, dtype=np.float64))))
        self.arm_last = (float(t), np.array(q, dtype=np.float64))
        if len(self.series) >= ARM_BATCH and last_frame_t < t - SERIES_FLUSH_S:   # no frames come
            self.flush(t)
            self.arm(*self.arm_last)

    def flush(self, t: float | None = None) -> None:
        """Write the queued series as one column chunk per entity (`send_columns`)."""
        rows = []
        while True:
            try:
                rows.append(self.series.popleft())
            except IndexError:
                break
        if t is not None:
            self.flushed_t = t
        by_entity: dict[str, list[tuple]] = {}
        for r in rows:
            by_entity.setdefault(r[0], []).append(r)
        with self.rec._lock:
            for entity, rs in by_entity.items():
                indexes = [rr.TimeColumn("time", duration=[r[1] for r in rs])]
                if all(r[2] is not None for r in rs):
                    indexes.append(rr.TimeColumn("frame", sequence=[int(r[2]) for r in rs]))
                self.rec._rec.send_columns(entity, indexes=indexes,
                                           columns=rr.Scalars.columns(scalars=np.array([r[3] for r in rs])))

    def arm(self, t: float, q: np.ndarray) -> None:
        """The arm's link frames and skeleton at joint angles q (rad), and the flange path."""
        frames = fk_frames(q)
        self.arm_drawn_t = t
        with self.rec._lock:
            self.rec._rec.reset_time()
            self.rec._rec.set_time("time", duration=t)
            for i, T in enumerate(frames):
                self.rec._rec.log(f"world/arm/link{i}", transform(T), rr.TransformAxes3D(axis_length=40.0))
            self.rec._rec.log("world/arm/skeleton", rr.LineStrips3D([frames[:, :3, 3]], radii=8.0,
                                                                       colors=[[200, 200, 200]]))
            self.path_pts.append((t, frames[-1, :3, 3].copy()))
            while self.path_pts and self.path_pts[0][0] < t - PATH_S:
                self.path_pts.popleft()
            if t - self.path_last_t >= PATH_PERIOD_S:
                self.path_last_t = t
                self.rec._rec.log("world/flange/path", rr.LineStrips3D(
                    [np.array([p for _, p in self.path_pts])], radii=2.0, colors=[[255, 255, 0]]))

    def close(self) -> None:
        """Write what is queued and the arm's last pose (the recording's end)."""
        self.flush()
        if self.arm_last is not None:
            self.arm(*self.arm_last)

