"""The tracker's configuration, [tracker] (vision/tracker.py): the per-frame GA, the motion
model, the measurement tests and the searches after a loss or from the whole volume."""

from __future__ import annotations

import math
from dataclasses import dataclass

from photoservo.errors import InputError


@dataclass(frozen=True)
class TrackerParams:
    """[tracker] config: the per-frame GA, the motion model, the measurement tests, the search."""

    generations_per_frame: int  # most GA generations per camera frame
    time_budget_ms: float  # stop a frame's generations once this much time is spent (ms)
    window_position_mm: float  # search window: +- this around the predicted position (mm)...
    window_growth_mm_s: float  # ...plus this much per second since the last measurement (mm/s)
    window_heading_deg: float  # ... +- this around the predicted heading (deg)
    window_tilt_deg: float  # ... +- this around the predicted tilt (deg)
    window_alpha_frac: float  # ... alpha within a factor 1 +- this of the track's
    lost_frames: int  # misses in a row before the track is declared lost...
    coast_max_s: float  # ...or this long without a measurement (s), whichever comes first
    gain_position: float  # alpha-beta filter: position gain (0..1)
    gain_velocity: float  # alpha-beta filter: velocity gain (0..1)
    gain_alpha: float  # smoothing of the size ratio alpha (0..1)
    size_tolerance: float  # re-acquisition: candidate alpha within this fraction of the track's
    max_speed_mm_s: float  # a measured jump faster than this is a miss, not a move (mm/s)
    water_z_mm: float  # water surface height in the base frame (mm); nan = unknown
    plane_search: bool  # search only on the water plane (position on it, heading, alpha)
    plane_margin_mm: float  # known water: a measured origin farther than this from the plane is a miss (mm)
    max_tilt_deg: float  # known water: a measured normal farther than this from the vertical is a miss (deg)
    min_visible: float  # share of S_in inside each image needed to measure; a prediction below: out_of_view
    search_window_mm: float  # lost: the position window grows up to +- this across the view (mm)
    acquire_generations: int  # whole-volume search: GA generations of it per camera frame

    def validate(self, where: str) -> None:
        w = f"{where}." if where else ""
        for k in ("generations_per_frame", "lost_frames", "acquire_generations"):
            if getattr(self, k) < 1:
                raise InputError(f"config key '{w}{k}': must be >= 1, got {getattr(self, k)}")
        for k in ("gain_position", "gain_velocity", "gain_alpha"):
            if not 0.0 < getattr(self, k) <= 1.0:
                raise InputError(f"config key '{w}{k}': must be in (0, 1], got {getattr(self, k)}")
        if self.plane_search and not math.isfinite(self.water_z_mm):
            raise InputError(f"config key '{w}plane_search': needs '{w}water_z_mm' (photoservo calibrate water)")
        for k in ("time_budget_ms", "window_position_mm", "window_alpha_frac", "max_speed_mm_s", "search_window_mm",
                  "coast_max_s"):
            if getattr(self, k) <= 0:
                raise InputError(f"config key '{w}{k}': must be > 0, got {getattr(self, k)}")
