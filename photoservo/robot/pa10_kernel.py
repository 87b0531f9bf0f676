"""Compiled (numba) forward kinematics of the PA-10 (method step 6): the link frames of
`pa10.fk_frames` for a batch of joint configurations, one 4x4 product per joint written out.

The control loop calls the kinematics five times a period at 250 Hz (the servo law's pose and
Jacobian, the keep-out's feature points and their Jacobians, the braking check's clearance) and
the keep-out's continuous checks call it on tens of sampled configurations; numpy spent ~60 us a
call on building and multiplying 4x4 arrays. Imported lazily by `pa10.fk_frames` (importing numba
costs ~0.3 s, which CLI verbs that never move an arm should not pay).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def fk_frames_kernel(Q: np.ndarray, a: np.ndarray, d: np.ndarray, ca: np.ndarray, sa: np.ndarray,
                     F: np.ndarray) -> None:
    """F[n] (8, 4, 4) = the link frames in the base frame at joints Q[n] (rad), Q (N, 7):
    F[n, 0] = I, F[n, i + 1] = F[n, i] · A_i(Q[n, i]) with the standard DH transform
    A_i = Rz(q_i) · Tz(d_i) · Tx(a_i) · Rx(alpha_i) (a, d in mm; ca, sa = cos, sin alpha_i)."""
    for n in range(Q.shape[0]):
        for r in range(4):
            for c in range(4):
                F[n, 0, r, c] = 1.0 if r == c else 0.0
        for i in range(Q.shape[1]):
            ct = math.cos(Q[n, i])
            st = math.sin(Q[n, i])
            # A_i = [[ct, -st·ca, st·sa, a·ct], [st, ct·ca, -ct·sa, a·st], [0, sa, ca, d], [0, 0, 0, 1]]
            for r in range(3):
                p0, p1, p2, p3 = F[n, i, r, 0], F[n, i, r, 1], F[n, i, r, 2], F[n, i, r, 3]
                F[n, i + 1, r, 0] = p0 * ct + p1 * st
                F[n, i + 1, r, 1] = (p1 * ct - p0 * st) * ca[i] + p2 * sa[i]
                F[n, i + 1, r, 2] = (p0 * st - p1 * ct) * sa[i] + p2 * ca[i]
                F[n, i + 1, r, 3] = (p0 * ct + p1 * st) * a[i] + p2 * d[i] + p3
            F[n, i + 1, 3, 0] = 0.0
            F[n, i + 1, 3, 1] = 0.0
            F[n, i + 1, 3, 2] = 0.0
            F[n, i + 1, 3, 3] = 1.0
