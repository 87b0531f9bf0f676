"""Compiled (numba) kernel of the stereo fitness (method step 3): the same case counts as
`fitness.counts_reference`, per (individual, camera): the plane map of the pose, a projection
loop writing the nearest pixel's flat index of every sampling point (branch-free, one division
per point without distortion), then a counting loop reading the hue there.

Imported lazily by `fitness.fitness` (importing numba costs ~0.3 s, which CLI verbs that never
score a pose should not pay). Compiled code is cached on disk (`cache=True`): the first call in
a fresh checkout compiles for a few seconds, later processes load the cache.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


def camera_vector(K: np.ndarray, dist: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """One camera's intrinsics for the kernel: fx, fy, cx, cy, width, height, k1, k2, p1, p2,
    k3, k4, k5, k6, model (0: no distortion, 1: polynomial k1 k2 p1 p2 k3, 2: rational, with
    k4 k5 k6)."""
    d = [float(x) for x in dist[:8]] + [0.0] * (8 - min(8, len(dist)))
    model = 2.0 if any(d[5:]) else 1.0 if any(d) else 0.0
    return np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], size[0], size[1], *d, model])


# fastmath without 'nnan'/'ninf': the behind-camera and in-image tests must see NaN and inf.
_FAST = {"nsz", "arcp", "contract", "afn", "reassoc"}


@njit(cache=True, error_model="numpy", fastmath=_FAST, nogil=True)
def _plane_map(R, t, alpha, rig_R, rig_T, cam, right, a):  # pragma: no cover - compiled
    """a <- the map from model-plane pixels (u, v, 1) of one individual to camera c (c = right
    or left): M = [r1/alpha | r2/alpha | t] in the left camera, R_s·M + [0 | 0 | T_s] in the
    right one; for a camera without distortion K·M, the plane-to-image homography."""
    M = np.empty((3, 3))
    for r in range(3):
        M[r, 0] = R[r, 0] / alpha
        M[r, 1] = R[r, 1] / alpha
        M[r, 2] = t[r]
    if right:
        for r in range(3):
            for c in range(3):
                a[r, c] = rig_R[r, 0] * M[0, c] + rig_R[r, 1] * M[1, c] + rig_R[r, 2] * M[2, c]
            a[r, 2] += rig_T[r]
    else:
        for r in range(3):
            for c in range(3):
                a[r, c] = M[r, c]
    if cam[14] == 0.0:
        for c in range(3):
            x, y, z = a[0, c], a[1, c], a[2, c]
            a[0, c] = cam[0] * x + cam[2] * z
            a[1, c] = cam[1] * y + cam[3] * z


@njit(cache=True, error_model="numpy", fastmath=_FAST, nogil=True)
def _pixel_indices(a, u_, v_, cam, idx):  # pragma: no cover - compiled
    """Nearest-pixel flat index (row·W + col) of every model-plane point (u_[k], v_[k]) px in one
    camera into idx[k], -1 when it falls outside the image or behind the camera; returns how
    many did. u_ and v_ are separate contiguous arrays: that lets the loop vectorise (3.5x faster
    than reading an (N, 2) array here). Pixel k covers [k - 0.5, k + 0.5): with f = x + 0.5, the point is in the image
    when 0 <= f < W, and then floor(f) == int(f) (truncation, cheap and vectorisable).

    Without distortion `a` is the plane-to-image homography: one division per point in a
    branch-free loop. With distortion `a` maps to the camera frame and OpenCV's model is applied
    to the normalised coordinates, as in rig.project_points. No 'nnan'/'ninf' fastmath here: a
    point near the camera's plane overflows to inf/NaN and must test as outside (full fastmath
    counted such points inside; the hypothesis test caught it). `_camera_counts` also clamps
    every index before it reads, so no point can ever read out of bounds.
    """
    W = cam[4]
    H = cam[5]
    w = np.int32(W)
    a00, a01, a02, a10, a11, a12, a20, a21, a22 = (
        a[0, 0], a[0, 1], a[0, 2], a[1, 0], a[1, 1], a[1, 2], a[2, 0], a[2, 1], a[2, 2])
    fx, fy, cx, cy = cam[0], cam[1], cam[2], cam[3]
    k1, k2, p1, p2, k3, k4, k5, k6 = cam[6], cam[7], cam[8], cam[9], cam[10], cam[11], cam[12], cam[13]
    outside = 0
    if cam[14] == 0.0:
        for k in range(u_.shape[0]):
            u = u_[k]
            v = v_[k]
            Z = a20 * u + a21 * v + a22
            iz = 1.0 / Z
            fc = (a00 * u + a01 * v + a02) * iz + 0.5
            fr = (a10 * u + a11 * v + a12) * iz + 0.5
            inside = (Z > 0.0) & (fc >= 0.0) & (fc < W) & (fr >= 0.0) & (fr < H)
            i = np.int32(fr if inside else 0.0) * w + np.int32(fc if inside else 0.0)
            idx[k] = i if inside else np.int32(-1)
            outside += np.int32(not inside)
    elif cam[14] == 1.0:  # polynomial k1 k2 p1 p2 k3: no second division
        for k in range(u_.shape[0]):
            u = u_[k]
            v = v_[k]
            Z = a20 * u + a21 * v + a22
            iz = 1.0 / Z
            x = (a00 * u + a01 * v + a02) * iz
            y = (a10 * u + a11 * v + a12) * iz
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
            yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
            fc = fx * xd + cx + 0.5
            fr = fy * yd + cy + 0.5
            inside = (Z > 0.0) & (fc >= 0.0) & (fc < W) & (fr >= 0.0) & (fr < H)
            i = np.int32(fr if inside else 0.0) * w + np.int32(fc if inside else 0.0)
            idx[k] = i if inside else np.int32(-1)
            outside += np.int32(not inside)
    else:  # rational model (k4 k5 k6)
        for k in range(u_.shape[0]):
            u = u_[k]
            v = v_[k]
            Z = a20 * u + a21 * v + a22
            iz = 1.0 / Z
            x = (a00 * u + a01 * v + a02) * iz
            y = (a10 * u + a11 * v + a12) * iz
            r2 = x * x + y * y
            radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
            xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
            yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
            fc = fx * xd + cx + 0.5
            fr = fy * yd + cy + 0.5
            inside = (Z > 0.0) & (fc >= 0.0) & (fc < W) & (fr >= 0.0) & (fr < H)
            i = np.int32(fr if inside else 0.0) * w + np.int32(fc if inside else 0.0)
            idx[k] = i if inside else np.int32(-1)
            outside += np.int32(not inside)
    return outside


@njit(cache=True, error_model="numpy", fastmath=_FAST, nogil=True)
def _camera_counts(R, t, alpha, rig_R, rig_T, cam, right, u, v, n_in, inner_hue, target_hues,
                   hue, tol, out):  # pragma: no cover - compiled
    """Case counts of one individual in one camera into out[0:5] (see fitness.IN_MATCH...);
    points (u[k], v[k]) px, the first n_in of them inner points."""
    a = np.empty((3, 3))
    _plane_map(R, t, alpha, rig_R, rig_T, cam, right, a)
    n = u.shape[0]
    idx = np.empty(n, np.int32)
    outside = _pixel_indices(a, u, v, cam, idx)
    flat = hue.ravel()
    last = flat.shape[0] - 1
    in_match = 0
    in_mis = 0
    out_match = 0
    out_mis = 0
    for k in range(n_in):
        i = idx[k]
        h = np.int32(flat[min(max(i, 0), last)])
        valid = np.int32((i >= 0) & (h < 180))  # NO_HUE (255) neither rewards nor punishes
        d = abs(h - np.int32(inner_hue[k]))
        d = min(d, 180 - d)
        agree = np.int32(d <= tol)
        in_match += valid & agree
        in_mis += valid & (1 - agree)
    for k in range(n_in, n):
        i = idx[k]
        h = np.int32(flat[min(max(i, 0), last)])
        valid = np.int32((i >= 0) & (h < 180))
        target = np.int32(target_hues[min(h, 179)])
        out_mis += valid & target
        out_match += valid & (1 - target)
    out[0] = in_match
    out[1] = in_mis
    out[2] = out_match
    out[3] = out_mis
    out[4] = outside


@njit(cache=True, error_model="numpy", nogil=True)
def _split_points(inner_uv, outer_uv):  # pragma: no cover - compiled
    """(u, v, n_in): the inner then outer points' coordinates as two contiguous arrays."""
    n_in = inner_uv.shape[0]
    n = n_in + outer_uv.shape[0]
    u = np.empty(n)
    v = np.empty(n)
    for k in range(n_in):
        u[k] = inner_uv[k, 0]
        v[k] = inner_uv[k, 1]
    for k in range(outer_uv.shape[0]):
        u[n_in + k] = outer_uv[k, 0]
        v[n_in + k] = outer_uv[k, 1]
    return u, v, n_in


@njit(cache=True, error_model="numpy", fastmath=_FAST, nogil=True)
def counts_serial(R, t, alpha, rig_R, rig_T, cam_l, cam_r, inner_uv, inner_hue, outer_uv,
                  target_hues, hue_l, hue_r, tol):  # pragma: no cover - compiled
    """Case counts (P, 2, 5) — in-match, in-mismatch, out-match, out-mismatch, outside — of the
    population (R (P,3,3), t (P,3) mm, alpha (P,) px/mm; model in the left camera frame) in the
    left (0) and right (1) camera. cam_l, cam_r: `camera_vector`s; hue_l, hue_r: (H, W) uint8
    C-contiguous hue images; target_hues: (180,) bool."""
    P = R.shape[0]
    u, v, n_in = _split_points(inner_uv, outer_uv)
    counts = np.zeros((P, 2, 5), dtype=np.int64)
    for job in range(2 * P):  # one call site: the kernel is compiled (and inlined) once
        p = job // 2
        c = job % 2
        cam = cam_l if c == 0 else cam_r
        hue = hue_l if c == 0 else hue_r
        _camera_counts(R[p], t[p], alpha[p], rig_R, rig_T, cam, c == 1, u, v, n_in, inner_hue,
                       target_hues, hue, tol, counts[p, c])
    return counts


@njit(cache=True, error_model="numpy", fastmath=_FAST, nogil=True, parallel=True)
def counts_parallel(R, t, alpha, rig_R, rig_T, cam_l, cam_r, inner_uv, inner_hue, outer_uv,
                    target_hues, hue_l, hue_r, tol):  # pragma: no cover - compiled
    """`counts_serial` with the (individual, camera) jobs spread over numba's threads."""
    P = R.shape[0]
    u, v, n_in = _split_points(inner_uv, outer_uv)
    counts = np.zeros((P, 2, 5), dtype=np.int64)
    for job in prange(2 * P):
        p = job // 2
        c = job % 2
        cam = cam_l if c == 0 else cam_r
        hue = hue_l if c == 0 else hue_r
        _camera_counts(R[p], t[p], alpha[p], rig_R, rig_T, cam, c == 1, u, v, n_in, inner_hue,
                       target_hues, hue, tol, counts[p, c])
    return counts


@njit(cache=True, error_model="numpy", nogil=True)
def combine(counts, n_in, n_out, w, mode):  # pragma: no cover - compiled
    """fitness._combine, compiled: w = (w_inner_match, w_inner_mismatch, w_outer_match,
    w_outer_mismatch, w_outside); mode 0 mean, 1 min, 2 product."""
    P = counts.shape[0]
    F = np.zeros(P)
    den = w[0] * n_in + w[2] * n_out
    if den <= 0.0:
        return F
    for p in range(P):
        f = np.empty(2)
        for c in range(2):
            q = counts[p, c]
            f[c] = (w[0] * q[0] - w[1] * q[1] + w[2] * q[2] - w[3] * q[3] - w[4] * q[4]) / den
        if mode == 0:
            F[p] = 0.5 * (f[0] + f[1])
        elif mode == 1:
            F[p] = min(f[0], f[1])
        else:
            F[p] = max(f[0], 0.0) * max(f[1], 0.0)
    return F
