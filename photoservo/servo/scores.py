"""The run's scores, each defined ONCE here and used by `track --json` / the summary, the status
line, replay's comparison table (record/reader.run_metrics) and the benchmarks.

  hold error (mm)        distance from the rig's centre (midpoint of the two optical centres)
                         to where the servo law wants it: straight above the TRUE target's
                         origin by the controller's height (hover_mm, lower while collecting).
                         `hold_error_mm`. The summary's `hold_error_rms_mm` is its RMS over the
                         control periods from settle_s on while servoing; the replay table's row
                         its RMS over every recorded frame (approach included).
  hold yaw error (deg)   the camera x axis against the desired one, both on the horizontal
                         (servo/control.yaw_error_deg), over the same periods.
  track error (mm)       |estimated - true| target position (base frame): `track_error_mm`.
  jitter (mm)            RMS second difference of the estimated position over consecutive
                         found frames: shake that a constant-velocity drift does not add.
  commanded motion (rad/s)  total variation of the joint-velocity setpoints,
                         sum_k ||dq*[k] - dq*[k-1]||: how much the servo law changed its command.

Truth exists in simulation only (`Truth`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from photoservo.servo.control import desired_camera_pose, yaw_error_deg

Z_UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Truth:
    """The simulator's ground truth for scoring: `motion.pose(t)` -> T_base_target (4x4, mm) at
    scene time t (s), the target's size (mm) and an optional look-alike's motion."""

    motion: Any
    size_mm: tuple[float, float]
    distractor: Any = None


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


def rms(values: list[float]) -> float:
    return math.sqrt(float(np.mean(np.square(values)))) if len(values) else float("nan")


@dataclass
class Scores:
    """Per-run numbers: the hold against the TRUE target (simulation), tracking, timings."""

    frames: int = 0
    found: int = 0
    lost_events: int = 0
    acquisitions: int = 0
    hold_mm: list[float] = field(default_factory=list)  # hold error per control period, settled, servoing
    hold_yaw_deg: list[float] = field(default_factory=list)
    timings_ms: dict[str, list[float]] = field(default_factory=dict)
    collected: bool = False
    faults: list[str] = field(default_factory=list)
    distractor_min_mm: float = float("inf")  # closest the rig centre came to the look-alike (horizontal)
    dropped_frames: int = 0  # frames with no arm state at their capture time
    last_status: str | None = None

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

    def score_hold(self, truth: Truth, T_base_cam: np.ndarray, T_left_centre: np.ndarray, height_mm: float,
                   servoing: bool, t: float, settle_s: float) -> None:
        """One control period against the truth at scene time t (s): the hold error and yaw
        error from settle_s on while servoing, and the look-alike's distance."""
        if truth.distractor is not None:
            c = rig_centre(T_base_cam, T_left_centre)
            d = truth.distractor.pose(t)[:3, 3]
            self.distractor_min_mm = min(self.distractor_min_mm, float(np.linalg.norm((c - d)[:2])))
        if t >= settle_s and servoing:
            T_target = truth.motion.pose(t)
            self.hold_mm.append(hold_error_mm(T_base_cam, T_left_centre, T_target[:3, 3], height_mm))
            T_des = desired_camera_pose(T_target, truth.size_mm, height_mm, T_base_cam[:3, :3], T_left_centre)
            self.hold_yaw_deg.append(yaw_error_deg(T_base_cam, T_des))

    def summary(self) -> dict:
        """The session summary (`track --json`)."""
        return {
            "frames": self.frames, "found_ratio": self.found / max(1, self.frames),
            "lost_events": self.lost_events, "acquisitions": self.acquisitions,
            "dropped_frames": self.dropped_frames,
            "hold_error_rms_mm": rms(self.hold_mm), "hold_yaw_error_rms_deg": rms(self.hold_yaw_deg),
            "hold_error_max_mm": max(self.hold_mm, default=0.0),
            "collected": self.collected, "faults": list(self.faults),
            "timings_ms_median": {k: float(np.median(v)) for k, v in self.timings_ms.items()},
            "distractor_min_mm": self.distractor_min_mm,
        }
