"""The tracker's motion model of the target (method step 5, issues 5 and 10; vision/tracker.py),
in the arm's BASE frame (z up, mm, s): an alpha-beta filter on position and velocity, the
orientation as last measured, the size ratio alpha smoothed (the creature's size does not
change), and on known water the height from the fitted heave (vision/heave.py: a float rides
the waves, it does not climb at a constant vertical velocity). Pure: arrays in, arrays out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from photoservo.vision.heave import HEAVE_WINDOW_S, Heave, fit_heave

FIRST_VELOCITY_S = 0.1  # a first measurement this long after the one that started the motion gives its velocity (s)
HEAVE_HORIZON_S = 0.25  # known water, no heave fitted yet: the vertical velocity is extrapolated this long at most (s)


@dataclass
class MotionModel:
    """Filtered target state: position p and velocity v (mm, mm/s), orientation R, alpha
    (px/mm), the time of the last measurement t_last (s), and on known water (water_z_mm
    finite) the recent measured heights and their heave. p is None before a measurement."""

    gain_position: float  # alpha-beta filter: position gain (0..1)
    gain_velocity: float  # alpha-beta filter: velocity gain (0..1)
    gain_alpha: float  # smoothing of alpha (0..1)
    water_z_mm: float  # known water height (mm); nan = unknown
    p: np.ndarray | None = None
    v: np.ndarray = field(default_factory=lambda: np.zeros(3))
    R: np.ndarray | None = None
    alpha: float | None = None
    t_last: float | None = None
    heights: list[tuple[float, float]] = field(default_factory=list)  # (t s, z mm) measured
    heave: Heave | None = None
    fresh: bool = True  # the velocity is not measured yet (no second measurement since the start)

    def restart(self) -> None:
        """The motion starts afresh (a creature back in view, a whole-volume search's answer):
        no position, velocity or heave; orientation and alpha kept."""
        self.p, self.t_last, self.v = None, None, np.zeros(3)
        self.heights, self.heave, self.fresh = [], None, True

    def predict(self, t: float) -> np.ndarray | None:
        """T_base_model predicted at time t (s): constant velocity, orientation held; on known
        water the height is the fitted heave's (an oscillation about a level), or before there is
        one the vertical velocity is extrapolated for at most HEAVE_HORIZON_S (a creature hidden
        for seconds still floats on the water). None before a measurement."""
        if self.p is None or self.R is None or self.t_last is None:
            return None
        dt = t - self.t_last
        T = np.eye(4)
        T[:3, :3] = self.R
        T[:3, 3] = self.p + self.v * dt
        if self.heave is not None:
            T[2, 3] = self.heave.z(t)
        elif math.isfinite(self.water_z_mm):
            T[2, 3] = self.p[2] + self.v[2] * min(dt, HEAVE_HORIZON_S)
        return T

    def velocity(self, t: float) -> np.ndarray:
        """The target's velocity at time t (mm/s): the filter's, vertically the heave's."""
        v = self.v.copy()
        if self.heave is not None:
            v[2] = self.heave.vz(t)
        return v

    def correct(self, T_bm: np.ndarray, alpha_m: float, t: float, restart: bool = False) -> None:
        """A measurement T_bm (4x4, base frame) with alpha_m (px/mm) at time t (s): alpha-beta
        update of position and velocity, orientation taken as measured, alpha smoothed;
        `restart`: the position taken as measured, the velocity kept — or, the first time after
        the motion started (a whole-volume search's answer confirmed on a newer frame, at least
        FIRST_VELOCITY_S later), measured from the two: at 2-5 fps with a generation or two per
        frame, a track that starts at rest never catches up with a drifting creature, and its
        prediction stays in view after the creature left (issue 10). On known water its height
        joins the last HEAVE_WINDOW_S of heights and the heave is fitted again."""
        p_m = T_bm[:3, 3]
        if self.p is None or self.t_last is None:
            self.p, self.v = p_m.copy(), np.zeros(3)
            self.alpha = float(alpha_m)
        elif restart:
            dt = t - self.t_last
            if self.fresh and dt >= FIRST_VELOCITY_S:
                self.v = (p_m - self.p) / dt
                self.fresh = False
            self.p = p_m.copy()
            self.alpha = float(self.alpha + self.gain_alpha * (alpha_m - self.alpha))
        else:
            dt = t - self.t_last
            pred = self.p + self.v * dt
            r = p_m - pred
            self.p = pred + self.gain_position * r
            if dt > 1e-3:  # a second measurement of one instant says nothing of the velocity
                self.v = self.v + (self.gain_velocity / dt) * r
                self.fresh = False
            self.alpha = float(self.alpha + self.gain_alpha * (alpha_m - self.alpha))
        self.R = T_bm[:3, :3].copy()
        self.t_last = t
        if math.isfinite(self.water_z_mm):
            self.heights = [h for h in self.heights if h[0] > t - HEAVE_WINDOW_S] + [(t, float(p_m[2]))]
            self.heave = fit_heave(*np.array(self.heights).T)
