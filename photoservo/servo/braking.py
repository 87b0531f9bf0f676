"""Jerk-limited braking, per joint or along a Cartesian direction (the safety layer of method
step 6: servo/motion.py's joint-range caps, servo/keepout.py's approach caps): how far a stop
from a speed takes, and the highest speed that can still stop within a distance. Units as the
arguments: rad or mm, per s, s², s³.
"""

from __future__ import annotations

import numpy as np


def stopping_distance(v: np.ndarray, a_max: np.ndarray, j_max: np.ndarray) -> np.ndarray:
    """Distance to stop from speed |v| with zero initial acceleration, jerk-limited:
    |v| <= a²/j: d = |v|·sqrt(|v|/j); else d = |v|/2 · (|v|/a + a/j)."""
    v = np.abs(v)
    return np.where(v <= a_max**2 / j_max, v * np.sqrt(v / j_max), 0.5 * v * (v / a_max + a_max / j_max))


def stopping_speed(d: np.ndarray, a_max: np.ndarray, j_max: np.ndarray) -> np.ndarray:
    """Inverse of `stopping_distance`: the highest speed that can still stop within d >= 0."""
    d = np.maximum(d, 0.0)
    short = (d * d * j_max) ** (1.0 / 3.0)
    long_ = 0.5 * (-a_max**2 / j_max + np.sqrt(a_max**4 / j_max**2 + 8.0 * a_max * d))
    return np.where(d <= a_max**3 / j_max**2, short, long_)
