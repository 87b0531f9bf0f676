"""Heave: the vertical motion of a creature floating on known water (issue 10, tracking that
holds). A float rides the waves: its height oscillates about the water plane, it does not move at
a constant vertical velocity. The tracker (vision/tracker.py) fits the recent measured heights
with one sinusoid about a level,

    z(t) = c + a · cos(ω t) + b · sin(ω t),

ω from a grid of wave periods (HEAVE_PERIODS_S), a, b, c by linear least squares for each ω, the
ω of the least residual kept; the fit predicts the height and the vertical velocity a few hundred
milliseconds ahead (where the GA's window is laid, where the servo law aims). A sea that is no one
sinusoid (an irregular one) explains less of the variance: below MIN_EXPLAINED no fit, and the
tracker's constant vertical velocity stands. Base frame, z up, mm, s. Pure: arrays in, a value object out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

HEAVE_PERIODS_S = np.geomspace(1.5, 12.0, 48)  # the wave periods tried (s)
HEAVE_WINDOW_S = 6.0  # the measurements of the last this many seconds are fitted (s)
MIN_SPAN_PERIODS = 0.6  # a fit needs measurements spanning this share of its period...
MIN_POINTS = 8  # ...and at least this many of them
MIN_EXPLAINED = 0.6  # ...and the sinusoid must explain this share of the heights' variance
# Checked on heave it was not made for (simulator's clock, hold RMS, old constant-velocity law -> this):
# an irregular sea (four sinusoids, periods 2.3-7.3 s) 8 fps 20.5 -> 20.3 mm, 30 fps 11.1 -> 15.1 mm
# (worse: the one sinusoid misleads where measurements are many); a 15-mm wake step at 8 fps
# 29.1 -> 15.1 mm, 30 fps 11.4 -> 13.7 (worse too).
# A stricter fit (0.9) or a shorter window (2.5 s) did not remove the 30-fps loss.


@dataclass(frozen=True)
class Heave:
    """A fitted heave: level c (mm), cos/sin amplitudes a, b (mm), angular frequency w (rad/s),
    about the time origin t_ref (s; the fit's times are t - t_ref). Extrapolates at most
    horizon_s past the last measurement (t_last): beyond it the level c alone."""

    c: float
    a: float
    b: float
    w: float
    t_ref: float
    t_last: float
    horizon_s: float = 1.0

    def z(self, t: float) -> float:
        """Height at time t (mm, base frame)."""
        if t - self.t_last > self.horizon_s:
            return self.c
        s = self.w * (t - self.t_ref)
        return self.c + self.a * math.cos(s) + self.b * math.sin(s)

    def vz(self, t: float) -> float:
        """Vertical velocity at time t (mm/s)."""
        if t - self.t_last > self.horizon_s:
            return 0.0
        s = self.w * (t - self.t_ref)
        return self.w * (self.b * math.cos(s) - self.a * math.sin(s))

    def shifted(self, dt: float) -> "Heave":
        """The same heave on a clock dt (s) ahead: its z(t + dt) is this one's z(t)."""
        return Heave(self.c, self.a, self.b, self.w, self.t_ref + dt, self.t_last + dt, self.horizon_s)

    @property
    def amplitude_mm(self) -> float:
        return math.hypot(self.a, self.b)


def fit_heave(t: np.ndarray, z: np.ndarray, periods_s: np.ndarray = HEAVE_PERIODS_S) -> Heave | None:
    """The heave of measured heights z (mm) at times t (s): the sinusoid about a level of least
    squared residual over the grid of periods whose measurements span at least MIN_SPAN_PERIODS
    of it; None with fewer than MIN_POINTS measurements, no such period, or a fit explaining
    less than MIN_EXPLAINED of the variance (no wave to speak of: the level alone is as good).

    >>> t = np.arange(0.0, 5.0, 0.1)
    >>> h = fit_heave(t, -100.0 + 20.0 * np.sin(2 * np.pi * t / 4.0))
    >>> round(2 * np.pi / h.w, 1), round(h.amplitude_mm, 1), round(h.z(5.2), 1), round(h.vz(5.2), 1)  # -81.0, -9.7
    (4.0, 20.0, -80.9, -9.6)
    """
    t = np.asarray(t, dtype=float)
    z = np.asarray(z, dtype=float)
    if len(t) < MIN_POINTS:
        return None
    t_ref = float(t[-1])
    s = t - t_ref
    periods = periods_s[(s[-1] - s[0]) >= MIN_SPAN_PERIODS * periods_s]
    if not len(periods):
        return None
    w = 2.0 * np.pi / periods
    coef, resid = _fit_at(s, z, w)
    k = int(np.argmin(resid))
    if 0 < k < len(w) - 1:  # the grid's minimum refined by a parabola through its neighbours
        r0, r1, r2 = resid[k - 1], resid[k], resid[k + 1]
        d = 0.5 * (r0 - r2) / (r0 - 2.0 * r1 + r2) if r0 - 2.0 * r1 + r2 > 0 else 0.0
        w_k = np.array([w[k] * (w[k + 1] / w[k]) ** d])
        c_k, r_k = _fit_at(s, z, w_k)
        if r_k[0] <= resid[k]:
            w, coef, resid, k = w_k, c_k, r_k, 0
    var = float(np.sum((z - z.mean()) ** 2))
    if var <= 0.0 or 1.0 - resid[k] / var < MIN_EXPLAINED:
        return None
    c, a, b = (float(x) for x in coef[k])
    return Heave(c, a, b, float(w[k]), t_ref, t_ref)


def _fit_at(s: np.ndarray, z: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least squares of z = c + a cos(w s) + b sin(w s) for each angular frequency of w (rad/s)
    at once: the (len(w), 3) coefficients [c, a, b] and the (len(w),) squared residuals."""
    ph = w[:, None] * s[None, :]  # (nw, n)
    A = np.stack([np.ones_like(ph), np.cos(ph), np.sin(ph)], axis=2)  # (nw, n, 3)
    AtA = np.einsum("wni,wnj->wij", A, A) + 1e-9 * np.eye(3)
    coef = np.linalg.solve(AtA, np.einsum("wni,n->wi", A, z)[..., None])[..., 0]
    return coef, np.sum((np.einsum("wni,wi->wn", A, coef) - z) ** 2, axis=1)
