"""Compiled (numba) water pass of the synthetic renderer: for every pixel, the view ray, its hit
on the water plane z = 0 and the water's colour there — the same model as
`synthetic._shade_water` (the numpy reference, which documents the shading), fused into one loop.

Imported lazily by `synthetic.render_view`. Compiled code is cached on disk (`cache=True`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

TWO_PI = 2 * math.pi
INV_TWO_PI = 1 / (2 * math.pi)


@njit(cache=True, inline="always")
def _wrap_bilinear(tex: np.ndarray, fx: float, fy: float) -> float:
    """Bilinear sample of a tileable texture at texel coordinates (fx, fy), wrapping around
    (cv2.remap INTER_LINEAR + BORDER_WRAP, without its 1/32-texel weight quantisation)."""
    n_r, n_c = tex.shape
    x0 = math.floor(fx)
    y0 = math.floor(fy)
    wx = fx - x0
    wy = fy - y0
    c0 = int(x0) & (n_c - 1)  # the textures are 2^k texels square (`_texture` sizes 128, 256)
    r0 = int(y0) & (n_r - 1)
    c1 = (c0 + 1) & (n_c - 1)
    r1 = (r0 + 1) & (n_r - 1)
    top = tex[r0, c0] * (1 - wx) + tex[r0, c1] * wx
    bot = tex[r1, c0] * (1 - wx) + tex[r1, c1] * wx
    return top * (1 - wy) + bot * wy


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"nsz", "arcp", "contract", "afn", "reassoc"})
def water_pass(rays, R, C, waves, omega, t, ripple, dx_tex, dy_tex, drift, mott_tex, mottle, sun,
               colour, sky, glint, col, shade, P, water, d):
    """Fill col (H,W,3), shade (H,W), P (H,W,2), water (H,W) and d (H,W,3, unit world rays).

    rays: (H,W,3) camera-frame rays; R, C: camera-to-world rotation and centre (mm);
    waves: (n,4) rows kx, ky, amplitude, phase; omega: (n,) angular frequencies; ripple
    textures sampled at 2 mm/texel, mottle at 40 mm/texel (as the reference)."""
    H, W = shade.shape
    sx, sy, sz = sun[0], sun[1], sun[2]
    hs = max(1e-6, math.sqrt(sx * sx + sy * sy))
    for i in range(H):
        for j in range(W):
            rx, ry, rz = rays[i, j, 0], rays[i, j, 1], rays[i, j, 2]
            dxw = R[0, 0] * rx + R[0, 1] * ry + R[0, 2] * rz
            dyw = R[1, 0] * rx + R[1, 1] * ry + R[1, 2] * rz
            dzw = R[2, 0] * rx + R[2, 1] * ry + R[2, 2] * rz
            inv = 1.0 / math.sqrt(dxw * dxw + dyw * dyw + dzw * dzw)
            dxw *= inv
            dyw *= inv
            dzw *= inv
            d[i, j, 0] = dxw
            d[i, j, 1] = dyw
            d[i, j, 2] = dzw
            hit = dzw < -1e-9 and -C[2] / dzw > 0
            water[i, j] = hit
            s = -C[2] / dzw if hit else 0.0
            x = C[0] + s * dxw
            y = C[1] + s * dyw
            P[i, j, 0] = x
            P[i, j, 1] = y
            if not hit:
                for k in range(3):
                    col[i, j, k] = sky[k]
                shade[i, j] = 1.0
                continue
            gx = 0.0
            gy = 0.0
            for w in range(waves.shape[0]):
                # phase in double (|phase| reaches thousands of rad), reduced to [0, 2 pi) by floor
                # (not by %, whose exact fmod cost a third of the pass), cosine in single precision
                ph = waves[w, 0] * x + waves[w, 1] * y + waves[w, 3] - omega[w] * t
                ph -= TWO_PI * math.floor(ph * INV_TWO_PI)
                c = waves[w, 2] * math.cos(np.float32(ph))
                gx += c * waves[w, 0]
                gy += c * waves[w, 1]
            if ripple > 0:
                gx += ripple * _wrap_bilinear(dx_tex, (x + drift) / 2.0, y / 2.0)
                gy += ripple * _wrap_bilinear(dy_tex, (x + drift) / 2.0, y / 2.0)
            inv_len = 1.0 / math.sqrt(gx * gx + gy * gy + 1.0)
            dn = (-dxw * gx - dyw * gy + dzw) * inv_len
            cos_v = min(max(-dn, 0.0), 1.0)
            fres = 0.02 + 0.98 * (1 - cos_v) ** 5
            sh = min(max(1.0 + 2.5 / hs * (gx * sx + gy * sy), 0.6), 1.4)
            shade[i, j] = sh
            mott = 1 + mottle * _wrap_bilinear(mott_tex, x / 40.0, y / 40.0)
            kb = sh * mott * (1 - fres)
            spec = 0.0
            if glint > 0:
                ns = (-gx * sx - gy * sy + sz) * inv_len
                ds = dxw * sx + dyw * sy + dzw * sz
                rs = ds - 2 * dn * ns
                if rs > 0.98:  # below, rs**600 < 6e-6: no glint
                    spec = glint * 900 * math.exp(600 * math.log(min(rs, 1.0)))
            for k in range(3):
                col[i, j, k] = colour[k] * kb + sky[k] * fres + spec


def shade_water(rays: np.ndarray, R: np.ndarray, C: np.ndarray, waves: np.ndarray, t: float, ripple: float,
                dx_tex: np.ndarray, dy_tex: np.ndarray, mott_tex: np.ndarray, mottle: float, sun, colour, sky,
                glint: float):
    """Run `water_pass` on fresh arrays: (col, shade, P, water, d)."""
    for tex in (dx_tex, dy_tex, mott_tex):  # `_wrap_bilinear` wraps by bit mask
        if any(n & (n - 1) or n == 0 for n in tex.shape):
            raise ValueError(f"water texture of shape {tex.shape}: sides must be powers of two")
    H, W = rays.shape[:2]
    col = np.empty((H, W, 3), np.float32)
    shade = np.empty((H, W), np.float32)
    P = np.empty((H, W, 2), np.float32)
    water = np.empty((H, W), np.bool_)
    d = np.empty((H, W, 3), np.float32)
    waves = np.ascontiguousarray(waves, np.float64).reshape(-1, 4)
    omega = np.sqrt(9810.0 * np.hypot(waves[:, 0], waves[:, 1]))
    water_pass(np.ascontiguousarray(rays, np.float64), np.ascontiguousarray(R, np.float64),
               np.ascontiguousarray(C, np.float64), waves, omega, float(t), float(ripple),
               dx_tex, dy_tex, 20.0 * float(t), mott_tex, float(mottle), np.asarray(sun, np.float64),
               np.asarray(colour, np.float64), np.asarray(sky, np.float64), float(glint), col, shade, P, water, d)
    return col, shade, P, water, d


# ----------------------------------------------------------------------------- floaters (fast path)


@njit(cache=True, nogil=True, error_model="numpy")
def world_rays(rays, R, d):
    """d (h,w,3 float32) <- unit world rays of camera-frame rays (h,w,3) for camera rotation R:
    `renderer._world_rays` (R · ray in double, then float32 and normalised in float32) fused."""
    h, w = d.shape[:2]
    for i in range(h):
        for j in range(w):
            x, y, z = rays[i, j, 0], rays[i, j, 1], rays[i, j, 2]
            a = np.float32(x * R[0, 0] + y * R[0, 1] + z * R[0, 2])
            b = np.float32(x * R[1, 0] + y * R[1, 1] + z * R[1, 2])
            c = np.float32(x * R[2, 0] + y * R[2, 1] + z * R[2, 2])
            n = np.sqrt(a * a + b * b + c * c)
            d[i, j, 0] = a / n
            d[i, j, 1] = b / n
            d[i, j, 2] = c / n


def window_rays(rays: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Run `world_rays` into a fresh float32 array (a floater's image window, fast path)."""
    d = np.empty(rays.shape, np.float32)
    world_rays(rays, np.ascontiguousarray(R, np.float64), d)
    return d


@njit(cache=True, nogil=True, error_model="numpy")
def floater_hits(d, Tm, o, alpha, ox, oy, W, H, bend, half_w, u, v, valid, near):
    """`renderer._floater_layer`'s map from image to photo, fused: for unit world rays d (h,w,3)
    from a camera at model-frame centre o (mm), their hit on the floater's surface (the model
    plane z = 0, or with bend != 0 the sheet z = -bend (x / half_w)^2 by 8 fixed-point steps)
    and the photo pixel there: u, v (px, -1e4 where no hit in front), valid (a hit in front),
    near (valid and within a pixel of the W x H photo). Tm: world -> model rotation (3x3)."""
    h, w = valid.shape
    for i in range(h):
        for j in range(w):
            d0, d1, d2 = np.float64(d[i, j, 0]), np.float64(d[i, j, 1]), np.float64(d[i, j, 2])
            m0 = d0 * Tm[0, 0] + d1 * Tm[0, 1] + d2 * Tm[0, 2]
            m1 = d0 * Tm[1, 0] + d1 * Tm[1, 1] + d2 * Tm[1, 2]
            m2 = d0 * Tm[2, 0] + d1 * Tm[2, 1] + d2 * Tm[2, 2]
            s = -o[2] / m2 if abs(m2) > 1e-12 else np.nan
            if bend != 0.0:
                for _ in range(8):
                    xb = (o[0] + s * m0) / half_w
                    s = (-bend * (xb * xb) - o[2]) / m2
            ok = math.isfinite(s) and s > 0
            uu = (o[0] + s * m0) * alpha + ox if ok else -1e4
            vv = (o[1] + s * m1) * alpha + oy if ok else -1e4
            u[i, j] = uu
            v[i, j] = vv
            valid[i, j] = ok
            near[i, j] = ok and uu > -2 and vv > -2 and uu < W + 1 and vv < H + 1


@njit(cache=True, nogil=True, error_model="numpy")
def footprint_values(u, v, near, out):
    """max(|d(u,v)/dx|, |d(u,v)/dy|) (photo px per image px, forward differences) at every
    pixel whose right and lower neighbours are `near` too, into out; returns their count."""
    h, w = near.shape
    n = 0
    for i in range(h - 1):
        for j in range(w - 1):
            if near[i, j] and near[i + 1, j] and near[i, j + 1]:
                ux, vx = u[i, j + 1] - u[i, j], v[i, j + 1] - v[i, j]
                uy, vy = u[i + 1, j] - u[i, j], v[i + 1, j] - v[i, j]
                out[n] = max(math.sqrt(ux * ux + vx * vx), math.sqrt(uy * uy + vy * vy))
                n += 1
    return n


@njit(cache=True, nogil=True, error_model="numpy")
def composite_floater(img, r0, c0, col, cov, valid, shade):
    """Lay a floater's layer over img[r0:, c0:] (float32 BGR): coverage cov (0 where not valid,
    clipped to 0..1) over the un-premultiplied colour col / cov, shaded by the swell
    (0.95 + 0.12 (shade - 1)); float32 arithmetic throughout, as the numpy expressions it replaces."""
    h, w = cov.shape
    one, eps = np.float32(1.0), np.float32(1e-4)
    for i in range(h):
        for j in range(w):
            c = cov[i, j] if valid[i, j] else np.float32(0.0)
            k = np.float32(0.95) + np.float32(0.12) * (shade[r0 + i, c0 + j] - one)
            a = min(max(c, np.float32(0.0)), one)
            for ch in range(3):
                x = col[i, j, ch] / max(c, eps) if c > eps else np.float32(0.0)
                img[r0 + i, c0 + j, ch] = img[r0 + i, c0 + j, ch] * (one - a) + (x * k) * a
