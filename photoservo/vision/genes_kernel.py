"""Compiled (numba) decoding of the GA's genes into poses (method step 4): what
`genes.GeneSpace.decode` computes, in one pass per individual. The tracker decodes its
population two or three times a generation (the water gates, the fitness, the best individual);
the numpy version (`GeneSpace.decode_reference`, ~50 small array operations) cost about as much
as the fitness kernel itself there.

Same formulas and the same floating-point operations in the same order as the numpy version
(no fastmath), so poses agree to the last bit or within an ulp of the libm sine and cosine.
Compiled code is cached on disk (`cache=True`); the session's warm start loads or compiles it
(`vision/warm.py`).
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, error_model="numpy", nogil=True)
def decode_genes(g, image, tilt_max, K, fx, limits, rig_R, rig_T, cams, R, t, alpha, valid):  # pragma: no cover - compiled
    """Genes g (P, 7) -> R (P,3,3), t (P,3) mm, alpha (P,) px/mm and valid (P,), written in place.

    image: image coding (u, v, q, psi, tilt_x, tilt_y, ln s), else cartesian (x, y, z, psi,
    tilt_x, tilt_y, ln alpha); tilt_max (rad): every tilt is clamped onto it once any exceeds it;
    K: the left camera's 3x3; fx: its focal length (px); limits: z_min, z_max, alpha_min,
    alpha_max, the largest alpha*z (apparent size); rig_R, rig_T: X_right = rig_R X_left + rig_T;
    cams: per camera (left, right) fx, fy, cx, cy, width, height (pinhole test of the origin)."""
    P = g.shape[0]
    clamp = False
    for p in range(P):
        if g[p, 4] * g[p, 4] + g[p, 5] * g[p, 5] > tilt_max * tilt_max:
            clamp = True
    for p in range(P):
        tx, ty = g[p, 4], g[p, 5]
        if clamp:
            shrink = min(1.0, tilt_max / math.sqrt(max(tx * tx + ty * ty, 1e-24)))
            tx, ty = tx * shrink, ty * shrink
        _rotation(g[p, 3], tx, ty, R[p])
        if image:
            z = 1000.0 / g[p, 2]
            t[p, 0] = (g[p, 0] - K[0, 2]) * (z / K[0, 0])
            t[p, 1] = (g[p, 1] - K[1, 2]) * (z / K[1, 1])
            t[p, 2] = z
            a = fx / (math.exp(g[p, 6]) * z)
        else:
            t[p, 0], t[p, 1], t[p, 2] = g[p, 0], g[p, 1], g[p, 2]
            z = g[p, 2]
            a = math.exp(g[p, 6])
        alpha[p] = a
        ok = (z >= limits[0] * 0.999) and (z <= limits[1] * 1.001)
        ok = ok and (a >= limits[2] * 0.999) and (a <= limits[3] * 1.001) and a * z <= limits[4]
        for c in range(2):
            X0, X1, X2 = t[p, 0], t[p, 1], t[p, 2]
            if c == 1:  # the right camera: rig_R X_left + rig_T
                X0, X1, X2 = (rig_R[0, 0] * X0 + rig_R[0, 1] * X1 + rig_R[0, 2] * X2 + rig_T[0],
                              rig_R[1, 0] * X0 + rig_R[1, 1] * X1 + rig_R[1, 2] * X2 + rig_T[1],
                              rig_R[2, 0] * X0 + rig_R[2, 1] * X1 + rig_R[2, 2] * X2 + rig_T[2])
            w = 1.0 / X2
            uc = X0 * w * cams[c, 0] + cams[c, 2]
            vc = X1 * w * cams[c, 1] + cams[c, 3]
            ok = ok and w > 0 and uc >= -0.5 and uc <= cams[c, 4] - 0.5 and vc >= -0.5 and vc <= cams[c, 5] - 0.5
        valid[p] = ok


@njit(cache=True, error_model="numpy", nogil=True, inline="always")
def _rotation(psi, tx, ty, R):  # pragma: no cover - compiled
    """R <- R_tilt(tx, ty) · Rz(psi), `geometry.rotation_from_heading_tilt` multiplied out."""
    th = math.hypot(tx, ty)
    small = th < 1e-12
    inv = 1.0 / (1.0 if small else th)
    kx = 1.0 if small else tx * inv
    ky = 0.0 if small else ty * inv
    s, c = math.sin(th), math.cos(th)
    v = 1.0 - c
    cp, sp = math.cos(psi), math.sin(psi)
    a00, a01, a02 = c + kx * kx * v, kx * ky * v, ky * s
    a10, a11, a12 = kx * ky * v, c + ky * ky * v, -kx * s
    a20, a21, a22 = -ky * s, kx * s, c
    R[0, 0] = a00 * cp + a01 * sp
    R[0, 1] = a01 * cp - a00 * sp
    R[0, 2] = a02
    R[1, 0] = a10 * cp + a11 * sp
    R[1, 1] = a11 * cp - a10 * sp
    R[1, 2] = a12
    R[2, 0] = a20 * cp + a21 * sp
    R[2, 1] = a21 * cp - a20 * sp
    R[2, 2] = a22
