"""The water surface of the simulated scenes (issue 2, item 7): its look (`Water`,
`calm_water`) and the shading model — deep-water wind waves, fine ripples, Fresnel sky
reflection, mottling and sun glints. `_shade_water` is the numpy reference of the renderer's
per-pixel water pass (sim/renderer_kernel.py); the textures are shared with the foam.

World frame: mm, z up, the water surface is the plane z = 0 (waves only tilt its normal).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

G_MM_S2 = 9810.0  # gravity, for deep-water wave dispersion (omega^2 = g k)


@dataclass(frozen=True)
class Water:
    """The water surface z = 0 (world, mm) and its look.

    colour_bgr: body colour of the water seen straight down; sky_bgr: colour of the sky it
    reflects (Fresnel, stronger at grazing view); waves: (n, 4) rows (kx, ky, amplitude_mm,
    phase) of deep-water sine waves, k in rad/mm; ripple: strength of fine ripples (slope);
    sun_dir: unit vector towards the sun (world); glint: strength of sun glints (0 = none);
    mottle: relative brightness variation over the surface; seed: texture seed."""

    colour_bgr: tuple[float, float, float]
    sky_bgr: tuple[float, float, float]
    waves: np.ndarray
    ripple: float
    sun_dir: tuple[float, float, float]
    glint: float
    mottle: float
    seed: int


def calm_water(seed: int, wave_slope: float = 0.06, glint: float = 1.0,
               sun_dir: tuple[float, float, float] = (0.3, 0.2, 0.93)) -> Water:
    """A harbour surface: teal water, six wind waves of 40-600 mm wavelength whose RMS slope is
    `wave_slope` (rad), fine ripples, and a sun at `sun_dir` (world, towards the sun)."""
    rng = np.random.default_rng([seed, 7])
    n = 6
    lam = np.exp(rng.uniform(np.log(40.0), np.log(600.0), n))
    k = 2 * np.pi / lam
    wind = rng.uniform(0, 2 * np.pi)
    ang = wind + rng.normal(0, 0.5, n)
    amp = (wave_slope * math.sqrt(2.0 / n)) / k  # each wave's slope amplitude a·k, RMS total
    waves = np.column_stack([k * np.cos(ang), k * np.sin(ang), amp, rng.uniform(0, 2 * np.pi, n)])
    hue_jit = rng.uniform(-1, 1)
    colour = (95.0 + 15 * hue_jit, 82.0 - 5 * hue_jit, 32.0 + rng.uniform(-8, 8))
    s = np.asarray(sun_dir, float)
    return Water(colour_bgr=colour, sky_bgr=(205.0, 195.0, 180.0), waves=waves, ripple=0.05,
                 sun_dir=tuple(s / np.linalg.norm(s)), glint=glint, mottle=0.06, seed=int(seed))


@functools.lru_cache(maxsize=32)
def _texture(seed: int, size: int, cell: float) -> np.ndarray:
    """Tileable smooth noise (float32, size x size, zero mean, unit std); memoised, read-only."""
    rng = np.random.default_rng([seed, int(cell * 10)])
    f = np.fft.fft2(rng.standard_normal((size, size)))
    k = np.fft.fftfreq(size)
    kk = np.hypot(*np.meshgrid(k, k))
    f *= np.exp(-(kk * cell) ** 2 * 4)
    t = np.real(np.fft.ifft2(f)).astype(np.float32)
    t = (t - t.mean()) / (t.std() + 1e-9)
    t.flags.writeable = False
    return t


@functools.lru_cache(maxsize=16)
def _ripple_slopes(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """x and y slopes of the ripple height texture (per texel), memoised, read-only."""
    tex = _texture(seed, 256, 3.0)
    dx = cv2.Sobel(tex, cv2.CV_32F, 1, 0, ksize=3) / 8
    dy = cv2.Sobel(tex, cv2.CV_32F, 0, 1, ksize=3) / 8
    dx.flags.writeable = dy.flags.writeable = False
    return dx, dy


def _sample_wrapped(tex: np.ndarray, x: np.ndarray, y: np.ndarray, mm_per_texel: float) -> np.ndarray:
    k = np.float32(1.0 / mm_per_texel)
    return cv2.remap(tex, (x * k).astype(np.float32), (y * k).astype(np.float32),
                     cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)


def _shade_water(w: Water, P: np.ndarray, d: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Colour (H, W, 3 float32, BGR 0..255) of the water at world points P (H, W, 2) seen along
    unit view rays d (H, W, 3): Fresnel mix of body colour and sky, light-field shading of the
    wave facets, mottling, sun glints. Also returns the shading factor (H, W) that floaters
    riding the same waves share. The surface normal is n = (-gx, -gy, 1)/|.| with (gx, gy) the
    slope of the wave height field."""
    x, y = P[..., 0], P[..., 1]
    gx = np.zeros_like(x)
    gy = np.zeros_like(x)
    for kx, ky, a, ph in w.waves:
        omega = math.sqrt(G_MM_S2 * math.hypot(kx, ky))
        c = np.float32(a) * np.cos(np.float32(kx) * x + np.float32(ky) * y + np.float32(ph - omega * t))
        gx += c * np.float32(kx)
        gy += c * np.float32(ky)
    if w.ripple > 0:
        dx, dy = _ripple_slopes(w.seed)
        drift = np.float32(20.0 * t)  # ripples drift with the wind (mm/s)
        gx += np.float32(w.ripple) * _sample_wrapped(dx, x + drift, y, 2.0)
        gy += np.float32(w.ripple) * _sample_wrapped(dy, x + drift, y, 2.0)
    inv_len = 1 / np.sqrt(gx * gx + gy * gy + 1)
    dn = (-d[..., 0] * gx - d[..., 1] * gy + d[..., 2]) * inv_len  # d . n
    cos_v = np.clip(-dn, 0.0, 1.0)
    fres = np.float32(0.02) + np.float32(0.98) * (1 - cos_v) ** 5
    sx, sy, sz = (float(v) for v in w.sun_dir)
    # light-field shading: facets tipped towards the sun are brighter (exaggerated, as the
    # sky's brightness gradient does on real water)
    hs = max(1e-6, math.hypot(sx, sy))
    shade = np.clip(1.0 + np.float32(2.5 / hs) * (gx * np.float32(sx) + gy * np.float32(sy)), 0.6, 1.4)
    mott = 1 + np.float32(w.mottle) * _sample_wrapped(_texture(w.seed + 1, 128, 4.0), x, y, 40.0)
    k_body = (shade * mott * (1 - fres))[..., None]
    col = np.asarray(w.colour_bgr, np.float32) * k_body + np.asarray(w.sky_bgr, np.float32) * fres[..., None]
    if w.glint > 0:
        ns = (-gx * np.float32(sx) - gy * np.float32(sy) + np.float32(sz)) * inv_len  # n . sun
        ds = d[..., 0] * np.float32(sx) + d[..., 1] * np.float32(sy) + d[..., 2] * np.float32(sz)
        rs = np.clip(ds - 2 * dn * ns, 0, 1)  # reflected ray . sun
        spec = rs ** 600
        col += (np.float32(w.glint * 900) * spec)[..., None]
    return col, shade
