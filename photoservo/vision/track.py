"""The tracker's answer for one frame (`Track`) and its status (vision/tracker.py, method step 5):
the value the servo law, the recorder and replay read. Poses in the arm's BASE frame (mm)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from photoservo.vision.heave import Heave

Status = Literal["acquiring", "tracking", "coasting", "lost", "out_of_view"]


@dataclass(frozen=True)
class Track:
    """The tracker's answer for one frame. Poses in the BASE frame (mm); `R_left`, `t_left` the
    measured pose in that frame's left camera (for drawing the model on the images)."""

    t: float  # capture time of the frame (s)
    status: Status
    found: bool  # this frame's best pose passed every test: a measurement
    fitness: float
    T_base_model: np.ndarray | None  # filtered target pose (tracking and coasting only)
    velocity_mm_s: np.ndarray  # filtered target velocity (base frame)
    alpha: float | None  # filtered px/mm
    size_mm: tuple[float, float] | None
    R_left: np.ndarray | None
    t_left: np.ndarray | None
    alpha_measured: float | None
    generations: int  # GA generations of the tracking search this frame
    seconds: float
    acquire_generations: int = 0  # GA generations of the whole-volume search this frame
    coast_s: float = 0.0  # how much older than the frame the measurement behind its pose is (s)
    heave: Heave | None = None  # known water: the fitted heave (vision/heave.py), its times relative to t
