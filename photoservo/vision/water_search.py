"""The tracking search on known water (issue 5 plane search, issue 10 plausibility gates): the
tracker's GA (vision/tracker.py) searches only poses a floating creature can take. Either on the
water plane itself (`on_plane`: [tracker] plane_search) or, by default, anywhere that passes
the water gates (`on_water_fitness`: the other poses score -inf).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from photoservo.vision.measurement import on_water
from photoservo.vision.pose_search import PoseSearch


def on_water_fitness(s: PoseSearch, T_base_left: np.ndarray, water_z_mm: float, margin_mm: float,
                     max_tilt_deg: float) -> Callable[[np.ndarray], np.ndarray]:
    """The search's fitness with the water gates (`measurement.on_water`; left camera at
    T_base_left, base frame mm): poses off the plane by more than margin_mm or tilted past
    max_tilt_deg score -inf, the others as the PoseSearch scores them (method step 3)."""
    def f(g: np.ndarray) -> np.ndarray:
        R, t, _, _ = s.space.decode(g)
        ok = on_water(T_base_left, R, t, water_z_mm, margin_mm, max_tilt_deg)
        out = np.full(len(g), -np.inf)
        if np.any(ok):
            out[ok] = s._fitness(g[ok])
        return out
    return f


def on_plane(g: np.ndarray, K: np.ndarray, T_left_base: np.ndarray, water_z_mm: float) -> np.ndarray:
    """Plane search (issue 5, Tracking): image-coded genes (u, v, q, psi, tilt_x, tilt_y, ln s)
    (vision/estimator.py) with the inverse depth q and the tilt replaced by those of a target
    lying flat on the water plane z = water_z_mm (base frame): the ray through (u, v) meets the
    plane at depth z, and the model normal (model z, down into the water) is -z_base seen from
    the camera. Only (u, v), the heading psi and the scale remain free."""
    g = np.array(g, dtype=np.float64, copy=True)
    R_lb = T_left_base[:3, :3]
    n = R_lb[:, 2]  # base z (up) in the left camera frame
    p0 = T_left_base[:3, :3] @ np.array([0.0, 0.0, water_z_mm]) + T_left_base[:3, 3]
    xn = (g[:, 0] - K[0, 2]) / K[0, 0]
    yn = (g[:, 1] - K[1, 2]) / K[1, 1]
    denom = n[0] * xn + n[1] * yn + n[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (n @ p0) / denom
    ok = np.isfinite(z) & (z > 1.0)
    g[ok, 2] = 1000.0 / z[ok]
    m = -n  # model normal
    th = math.atan2(math.hypot(m[0], m[1]), m[2])
    ax, ay = -m[1], m[0]
    norm = math.hypot(ax, ay)
    g[:, 4], g[:, 5] = (ax / norm * th, ay / norm * th) if norm > 1e-12 else (0.0, 0.0)
    return g
