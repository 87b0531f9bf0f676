"""The run's scores, each defined ONCE here and used by `track --json` / the summary, replay's
comparison table (record/compare.run_metrics), `tune` and the benchmarks.

  hold error (mm)        distance from the rig's centre (midpoint of the two optical centres)
                         to where the servo law wants it: [servo] hover_mm straight above the
                         TRUE target's origin (`hold_error_mm`), at each frame's capture time
                         (the left camera's pose then, the truth then: `hold_sample`). The
                         score (`hold_error_rms_mm`, the table's hold row) is its RMS over the
                         frames captured from [servo] settle_s on while the controller servoed
                         (not while collecting: `scored_holds`), so the live summary and the
                         table of the run's recording count the same frames with the same
                         numbers.
  hold yaw error (deg)   the camera x axis against the desired one, both on the horizontal
                         (servo/control.yaw_error_deg), over the same frames.
  track error (mm)       |estimated - true| target position (base frame): `track_error_mm`.
  jitter (mm)            RMS second difference of the estimated position over consecutive
                         found frames: shake that a constant-velocity drift does not add.
  commanded motion (rad/s)  total variation of the joint-velocity setpoints,
                         sum_k ||dq*[k] - dq*[k-1]||: how much the servo law changed its command.
  tracking against the truth (issue 10), per frame (`TruthFrame`): the summary's
    track_error_mm       {median, p95} of the track error over the frames where the creature is
                         fully in both views (all of S_in inside both images) and not hidden, and
                         the tracker gave a pose (tracking or coasting); track_error_partial_mm the
                         same over the frames where it is in view in part;
    false_tracks         frames reported tracking or coasting while the creature is out of view
                         (none of S_in inside an image) or the estimate is > 50 mm from the truth;
    reacquisition_s      per visibility gap (frames where it is not fully in view, or hidden by
                         foam, after it was), seconds from its first visible frame after the gap
                         to the first frame with status tracking (0: the track held through it;
                         None: not back before the next gap or the run's end).

Truth exists in simulation only (`Truth`).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from photoservo.servo.control import desired_camera_pose, yaw_error_deg
from photoservo.servo.controller import phase_of

Z_UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Truth:
    """The simulator's ground truth for scoring: `motion.pose(t)` -> T_base_target (4x4, mm) at
    scene time t (s), the target's size (mm) and an optional look-alike's motion."""

    motion: Any
    size_mm: tuple[float, float]
    distractor: Any = None
    in_view: Callable[[np.ndarray, float], float] | None = None  # (T_base_left, t) -> share of S_in in both images
    hidden: Callable[[float], bool] | None = None  # t -> foam over the creature


def rig_centre(T_base_left: np.ndarray, T_left_centre: np.ndarray) -> np.ndarray:
    """The rig's centre (mm, base frame) from the left camera's pose and the centre's offset in
    the left camera frame (servo/controller.left_centre)."""
    return T_base_left[:3, :3] @ T_left_centre + T_base_left[:3, 3]


def hold_error_mm(T_base_left: np.ndarray, T_left_centre: np.ndarray, p_target: np.ndarray,
                  height_mm: float) -> float:
    """Hold error (module docstring): |rig centre - (p_target + height_mm · z_base)| in mm.

    >>> hold_error_mm(np.eye(4), np.zeros(3), np.array([0.0, 30.0, -560.0]), 600.0)
    50.0
    """
    return float(np.linalg.norm(rig_centre(T_base_left, T_left_centre) - p_target - height_mm * Z_UP))


@dataclass(frozen=True)
class HoldSample:
    """One frame's hold against the truth: capture time t of its left image (s, session time),
    hold error (mm) and hold yaw error (deg) (module docstring)."""

    t: float
    error_mm: float
    yaw_deg: float


def hold_sample(t: float, T_base_left: np.ndarray, T_left_centre: np.ndarray, T_base_target: np.ndarray,
                size_mm: tuple[float, float], height_mm: float) -> HoldSample:
    """The hold of a frame captured at t (s) with the left camera at T_base_left (4x4, mm, base
    frame) over the true target at T_base_target (4x4, mm) of size_mm, at height_mm."""
    T_des = desired_camera_pose(T_base_target, size_mm, height_mm, T_base_left[:3, :3], T_left_centre)
    return HoldSample(float(t), hold_error_mm(T_base_left, T_left_centre, T_base_target[:3, 3], height_mm),
                      yaw_error_deg(T_base_left, T_des))


def scored_holds(samples: list[HoldSample], events: list[tuple[float, str]], settle_s: float) -> list[HoldSample]:
    """The samples the hold score counts: captured from settle_s (s) on while the controller was
    in phase "servo", by the phase events (t, text) among `events` (servo/controller.phase_event;
    other events are passed over). Samples keep their order.

    >>> s = [HoldSample(t, 1.0, 0.0) for t in (1.0, 2.0, 3.0, 4.0)]
    >>> [h.t for h in scored_holds(s, [(2.5, "phase descend: ..."), (3.5, "phase servo: ...")], 1.5)]
    [2.0, 4.0]
    """
    changes = sorted((t, p) for t, text in events if (p := phase_of(text)) is not None)
    times = [t for t, _ in changes]

    def servoing(t: float) -> bool:
        i = bisect.bisect_right(times, t)
        return i == 0 or changes[i - 1][1] == "servo"
    return [h for h in samples if h.t >= settle_s and servoing(h.t)]


def track_error_mm(p_estimate: np.ndarray, p_true: np.ndarray) -> float:
    """Track error (module docstring): |p_estimate - p_true| (mm, base frame)."""
    return float(np.linalg.norm(np.asarray(p_estimate) - np.asarray(p_true)))


def jitter_mm(positions: list[np.ndarray]) -> float:
    """Jitter (module docstring) of consecutive found positions (mm); NaN with fewer than 3."""
    d2 = [float(np.linalg.norm(c - 2 * b + a)) for a, b, c in zip(positions, positions[1:], positions[2:])]
    return float(np.sqrt(np.mean(np.square(d2)))) if d2 else float("nan")


def commanded_motion(setpoint_dq: np.ndarray) -> float:
    """Commanded motion (module docstring) of joint-velocity setpoints (N, 7) rad/s."""
    dq = np.asarray(setpoint_dq, dtype=float)
    return float(np.linalg.norm(np.diff(dq, axis=0), axis=1).sum()) if len(dq) > 1 else float("nan")


FULLY_IN_VIEW = 0.999  # a share of S_in in both images at least this: the creature fully in both views
FALSE_TRACK_MM = 50.0  # a pose farther than this from the truth is a false track (issue 10)
POSE_STATUSES = ("tracking", "coasting")  # the statuses that give the arm a pose


@dataclass(frozen=True)
class TruthFrame:
    """One frame against the simulator's truth: capture time (s), the tracker's status, the
    share of the creature's inner points S_in inside both images (`Truth.in_view`), foam over
    it (`Truth.hidden`), and |estimated - true| position (mm; nan without a pose)."""

    t: float
    status: str
    in_view: float
    hidden: bool
    error_mm: float

    @property
    def visible(self) -> bool:
        """Fully in both views and not hidden: the tracker can be asked to see it."""
        return self.in_view >= FULLY_IN_VIEW and not self.hidden


def track_error_summary(frames: list[TruthFrame], partial: bool = False) -> dict:
    """`track_error_mm` of the summary: {median, p95} of the track error over the frames where
    the creature is fully in both views (not hidden) and the tracker gave a pose; None without
    such frames. `partial`: over the frames where it is in view only in part instead
    (`track_error_partial_mm`: a creature leaving the view of a still arm).

    >>> track_error_summary([TruthFrame(0.0, "tracking", 1.0, False, 2.0), TruthFrame(0.1, "lost", 1.0, False, math.nan)])
    {'median': 2.0, 'p95': 2.0}
    """
    def counted(f: TruthFrame) -> bool:
        seen = 0.0 < f.in_view < FULLY_IN_VIEW and not f.hidden if partial else f.visible
        return seen and f.status in POSE_STATUSES and math.isfinite(f.error_mm)
    e = [f.error_mm for f in frames if counted(f)]
    if not e:
        return {"median": None, "p95": None}
    return {"median": float(np.median(e)), "p95": float(np.percentile(e, 95))}


def false_tracks(frames: list[TruthFrame]) -> int:
    """Frames reported tracking or coasting while the creature is out of view (none of it in
    both images) or the estimate is more than FALSE_TRACK_MM from the truth."""
    return sum(1 for f in frames if f.status in POSE_STATUSES
               and (f.in_view <= 0.0 or not f.error_mm <= FALSE_TRACK_MM))


def reacquisition_s(frames: list[TruthFrame]) -> list[float | None]:
    """Per visibility gap (frames not `visible` after it was visible), the seconds from the
    first visible frame after the gap to the first frame with status tracking (0 when the track
    held through the gap); None when the track did not come back before the creature left again
    or the run ended."""
    out: list[float | None] = []
    seen = in_gap = False
    t_back: float | None = None
    for f in frames:
        if t_back is not None:
            if f.status == "tracking":
                out.append(f.t - t_back)
                t_back = None
            elif not f.visible:
                out.append(None)
                t_back, in_gap = None, True
                continue
        if not f.visible:
            in_gap = seen
        elif in_gap:
            in_gap, t_back = False, f.t
            if f.status == "tracking":
                out.append(0.0)
                t_back = None
        seen = seen or f.visible
    if t_back is not None:
        out.append(None)
    return out


def rms(values: list[float]) -> float:
    return math.sqrt(float(np.mean(np.square(values)))) if len(values) else float("nan")


@dataclass
class Scores:
    """Per-run numbers: the hold against the TRUE target (simulation), tracking, timings."""

    frames: int = 0
    found: int = 0
    lost_events: int = 0
    acquisitions: int = 0
    settle_s: float = 5.0  # [servo] settle_s: the hold counts from here on (s, session time)
    holds: list[HoldSample] = field(default_factory=list)  # every frame's hold (simulation)
    phase_events: list[tuple[float, str]] = field(default_factory=list)  # the controller's, session time
    timings_ms: dict[str, list[float]] = field(default_factory=dict)
    collected: bool = False
    faults: list[str] = field(default_factory=list)
    distractor_min_mm: float = float("inf")  # closest the rig centre came to the look-alike (horizontal)
    dropped_frames: int = 0  # frames with no arm state at their capture time
    last_status: str | None = None
    first_track_s: float | None = None  # session time the servo law got its first tracking estimate (s)
    truth_frames: list[TruthFrame] = field(default_factory=list)  # simulation: each frame against the truth

    def time(self, stage: str, ms: float) -> None:
        self.timings_ms.setdefault(stage, []).append(ms)

    def note_track(self, found: bool, status: str) -> bool:
        """Count a frame's track; True when its status differs from the previous frame's."""
        self.frames += 1
        self.found += int(found)
        changed = status != self.last_status
        if changed:
            self.lost_events += status == "lost"
            self.last_status = status
        return changed

    def note_delivery(self, t: float, status: str) -> None:
        """The servo law got a track of `status` at session time t (s): the first tracking one
        is `first_track_s` (on a busy machine the first search can outlast the creature's stay)."""
        if status == "tracking" and self.first_track_s is None:
            self.first_track_s = t

    def score_track(self, truth: Truth, T_base_left: np.ndarray, t: float, status: str,
                    p_estimate: np.ndarray | None) -> TruthFrame:
        """One frame against the truth (`TruthFrame`): captured at scene time t (s) with the left
        camera at T_base_left, the tracker's status and estimated position (mm, base frame)."""
        err = math.nan if p_estimate is None else track_error_mm(p_estimate, truth.motion.pose(t)[:3, 3])
        f = TruthFrame(t, status, 1.0 if truth.in_view is None else truth.in_view(T_base_left, t),
                       truth.hidden is not None and truth.hidden(t), err)
        self.truth_frames.append(f)
        return f

    def score_hold(self, t: float, T_base_left: np.ndarray, T_left_centre: np.ndarray, truth: Truth,
                   height_mm: float) -> None:
        """A frame captured at scene time t (s) with the left camera at T_base_left, against the
        truth then (`hold_sample`); whether it counts is decided at the end (`scored_holds`)."""
        self.holds.append(hold_sample(t, T_base_left, T_left_centre, truth.motion.pose(t), truth.size_mm, height_mm))

    def score_distractor(self, t: float, T_base_cam: np.ndarray, T_left_centre: np.ndarray, truth: Truth) -> None:
        """The look-alike's horizontal distance from the rig centre at scene time t (s), if any."""
        if truth.distractor is not None:
            c = rig_centre(T_base_cam, T_left_centre)
            d = truth.distractor.pose(t)[:3, 3]
            self.distractor_min_mm = min(self.distractor_min_mm, float(np.linalg.norm((c - d)[:2])))

    def note_events(self, events: list[tuple[float, str]]) -> None:
        """Keep the controller's phase events (t in session time, s) for `scored_holds`."""
        self.phase_events += [(t, text) for t, text in events if phase_of(text) is not None]

    def held(self) -> list[HoldSample]:
        """The holds the score counts (`scored_holds`)."""
        return scored_holds(self.holds, self.phase_events, self.settle_s)

    def summary(self) -> dict:
        """The session summary (`track --json`)."""
        held = self.held()
        return {
            "frames": self.frames, "found_ratio": self.found / max(1, self.frames),
            "lost_events": self.lost_events, "acquisitions": self.acquisitions,
            "dropped_frames": self.dropped_frames,
            "hold_error_rms_mm": rms([h.error_mm for h in held]),
            "hold_yaw_error_rms_deg": rms([h.yaw_deg for h in held]),
            "hold_error_max_mm": max((h.error_mm for h in held), default=0.0),
            "collected": self.collected, "faults": list(self.faults),
            "timings_ms_median": {k: float(np.median(v)) for k, v in self.timings_ms.items()},
            "distractor_min_mm": self.distractor_min_mm, "final_status": self.last_status,
            "first_track_s": self.first_track_s,
            **({"track_error_mm": track_error_summary(self.truth_frames),
                "track_error_partial_mm": track_error_summary(self.truth_frames, partial=True),
                "false_tracks": false_tracks(self.truth_frames), "reacquisition_s": reacquisition_s(self.truth_frames)}
               if self.truth_frames else {}),
        }
