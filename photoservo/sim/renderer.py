"""Synthetic stereo views of a photo's target floating on water (issue 2, item 7).

This module renders from camera poses it is GIVEN (DESIGN.md): it never knows about the arm.
The arm simulator (sim/world.py) and the scene generator `random_scene` hand it poses.

Frames and units
  * World frame: mm, z up; the water surface is the plane z = 0 (waves only tilt its normal for
    shading — geometry stays flat, as a floating target rides the swell with it).
  * Camera frames: OpenCV (x right, y down, z forward). `T_world_cam` is a 4x4 with
    X_world = T_world_cam · X_cam.
  * A floater's model frame is the photo-model frame of DESIGN.md: a photo pixel (u, v) sits at
    ((u - ox)/alpha, (v - oy)/alpha, 0) mm, z into the photo. A creature lying face-up on the
    water therefore has its model z pointing down into the water: see `lying_on_water`.

API
  Water, Floater, Foam, Scene            value objects of a scene
  CameraEffects                          per-camera image effects (blur, gain, white balance,
                                         sensor noise, JPEG/MJPG chroma loss)
  render_view(scene, cam, T_world_cam, t, rng, effects) -> BGR uint8
  render_stereo(scene, rig, T_world_left, t, rng, effects) -> (left, right)
  StereoRenderer(rig).render(scene, T_world_left, t, rng, effects)   same, rays cached (video)
  lying_on_water(position_world, heading) -> T_world_model of a creature lying face-up
  SynthParams                            [synthetic] config section
  random_scene(seed, params, ...) -> SyntheticScene   images, rig written, rig used, truth JSON

Rendering: every pixel of the (distorted) image is undistorted to a ray (cv2.undistortPointsIter,
so the camera's lens distortion is honoured exactly), the ray is intersected with the water plane
and with each floater's surface (plane, or a gently bent sheet solved by fixed-point iteration),
and the photo is sampled there with premultiplied-alpha bilinear lookup from a photo prefiltered
to the on-screen footprint (anti-aliased edges, no backdrop fringe). The per-pixel water pass
runs as a numba kernel (synthetic_kernel.py); `_shade_water` is its numpy reference.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.geometry import axis_rotation
from photoservo.geometry import make_pose as make_transform  # one builder for vision/
from photoservo.vision.photo_model import PhotoModel, hue_distance
from photoservo.vision.rig import Camera, Rig

G_MM_S2 = 9810.0  # gravity, for deep-water wave dispersion (omega^2 = g k)


# ----------------------------------------------------------------------------- scene objects


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


@dataclass(frozen=True)
class Floater:
    """A flat textured object on the water: the masked part of `photo` (BGR uint8) scaled by
    1/alpha (px/mm) and placed by T_world_model (4x4, model frame of DESIGN.md -> world).
    bend_mm: the ends of the model's x axis are lifted this far out of the model plane (towards
    -z_model, i.e. out of the water for a creature lying face-up): z_model = -bend·(2x/width)²."""

    photo: np.ndarray
    mask: np.ndarray
    origin_px: tuple[float, float]
    alpha: float
    T_world_model: np.ndarray
    bend_mm: float = 0.0


@dataclass(frozen=True)
class Foam:
    """Foam patches floating on the water (world xy, mm): rows (x, y, radius_mm). Foam is white
    and carries no hue; it covers water and floaters alike."""

    patches: np.ndarray
    seed: int = 0


@dataclass(frozen=True)
class Scene:
    """What the cameras look at: water, an optional target, look-alike distractors, foam."""

    water: Water
    target: Floater | None = None
    distractors: tuple[Floater, ...] = ()
    foam: Foam | None = None


@dataclass(frozen=True)
class CameraEffects:
    """Per-camera image effects applied after rendering, in this order: Gaussian blur (sigma
    px), gain (brightness multiplier), white balance (B, G, R gains), sensor noise (sigma in
    8-bit DN), then a JPEG round trip at `jpeg_quality` with 4:2:0 chroma (0 = off), as MJPG
    cameras deliver."""

    blur_sigma: float = 0.0
    gain: float = 1.0
    white_balance: tuple[float, float, float] = (1.0, 1.0, 1.0)
    noise_sigma: float = 0.0
    jpeg_quality: int = 0


def lying_on_water(position_world: np.ndarray, heading: float) -> np.ndarray:
    """T_world_model of a creature lying face-up on the water at `position_world` (mm), its model
    x axis at `heading` (rad, about world z from world x). The model z axis points down."""
    R = axis_rotation(2, heading) @ np.diag([1.0, -1.0, -1.0])
    return make_transform(R, np.asarray(position_world, float))


def stereo_transform(rig: Rig) -> np.ndarray:
    """T_right_left (4x4): X_right = R · X_left + T."""
    return make_transform(rig.R, rig.T)


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


def floater_from_model(photo: np.ndarray, model: PhotoModel, alpha: float, T_world_model: np.ndarray,
                       bend_mm: float = 0.0) -> Floater:
    """A Floater of a photo's target as its photo-model cut it out (mask, origin)."""
    if not alpha > 0:
        raise InputError(f"alpha {alpha!r}: must be a positive px/mm ratio")
    return Floater(photo=photo, mask=model.mask, origin_px=model.origin_px, alpha=float(alpha),
                   T_world_model=np.asarray(T_world_model, float), bend_mm=float(bend_mm))


# ----------------------------------------------------------------------------- rendering


def pixel_rays(cam: Camera) -> np.ndarray:
    """(H, W, 3) rays (x, y, 1) in the camera frame through every pixel centre of the distorted
    image: the inverse of `project_points` (10 fixed-point undistortion iterations: ~1e-9 px for mild distortion)."""
    W, H = cam.size
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    pts = np.stack([u, v], -1).reshape(-1, 1, 2)
    if np.any(cam.dist):
        crit = (cv2.TERM_CRITERIA_COUNT, 10, 0.0)  # ~1e-9 px for mild distortion; EPS checks cost 3x
        xy = cv2.undistortPointsIter(pts, cam.K, cam.dist, None, None, crit).reshape(H, W, 2)
    else:
        xy = np.stack([(u - cam.K[0, 2]) / cam.K[0, 0], (v - cam.K[1, 2]) / cam.K[1, 1]], -1)
    return np.concatenate([xy, np.ones((H, W, 1))], axis=-1)


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


def _footprint(u: np.ndarray, v: np.ndarray, valid: np.ndarray, exact: bool = True) -> float:
    """Median photo pixels per image pixel over `valid` (from the map's finite differences).
    exact=False: lengths by sqrt(x² + y²) instead of np.hypot (~5x faster here; may differ in
    the last bit)."""
    if u.shape[0] < 2 or u.shape[1] < 2:
        return 1.0
    if exact:
        du = np.hypot(np.diff(u, axis=1)[:-1], np.diff(v, axis=1)[:-1])
        dv = np.hypot(np.diff(u, axis=0)[:, :-1], np.diff(v, axis=0)[:, :-1])
    else:
        ux, vx, uy, vy = np.diff(u, axis=1)[:-1], np.diff(v, axis=1)[:-1], np.diff(u, axis=0)[:, :-1], np.diff(v, axis=0)[:, :-1]
        du, dv = np.sqrt(ux * ux + vx * vx), np.sqrt(uy * uy + vy * vy)
    m = valid[:-1, :-1] & valid[1:, :-1] & valid[:-1, 1:]
    if not m.any():
        return 1.0
    return float(np.median(np.maximum(du[m], dv[m])))


def _window(cam: Camera, T_cam_world: np.ndarray, Xw: np.ndarray, margin: int = 4) -> tuple[slice, slice] | None:
    """Image window (rows, cols) holding the projection of world points Xw (the corners of a box
    around an object); the full image when a corner is behind the camera; None if off-image."""
    from photoservo.vision.rig import project_points

    Xc = Xw @ T_cam_world[:3, :3].T + T_cam_world[:3, 3]
    W, H = cam.size
    if np.any(Xc[:, 2] <= 1e-3):
        return slice(0, H), slice(0, W)
    uv = project_points(Xc, cam)
    # distortion can fold far-off-axis points back in: only trust corners near the image
    if not np.all(np.isfinite(uv)) or np.any(np.abs(Xc[:, :2] / Xc[:, 2:3]) > 2.0):
        return slice(0, H), slice(0, W)
    x0, y0 = np.floor(uv.min(0)).astype(int) - margin
    x1, y1 = np.ceil(uv.max(0)).astype(int) + margin + 1
    x0, y0, x1, y1 = max(0, x0), max(0, y0), min(W, x1), min(H, y1)
    if x0 >= x1 or y0 >= y1:
        return None
    return slice(y0, y1), slice(x0, x1)


def _floater_box(f: Floater) -> np.ndarray:
    """World corners of a box around a floater (its mask's rectangle, bend included)."""
    x, y, w, h = cv2.boundingRect(f.mask)
    xs = (np.array([x - 1, x + w]) - f.origin_px[0]) / f.alpha
    ys = (np.array([y - 1, y + h]) - f.origin_px[1]) / f.alpha
    zs = np.array([0.0, -abs(f.bend_mm) - 1.0, abs(f.bend_mm) + 1.0])
    P = np.array([[a, b, c] for a in xs for b in ys for c in zs])
    return P @ f.T_world_model[:3, :3].T + f.T_world_model[:3, 3]


def _photo_layers(photo: np.ndarray, mask: np.ndarray, size: tuple[int, int] | None) -> tuple[np.ndarray, np.ndarray]:
    """(premultiplied colour, coverage) float32 of a floater's photo: the mask softened into an
    anti-aliased coverage, the photo premultiplied by it, both shrunk to `size` (w, h;
    cv2.INTER_AREA: the prefilter to the on-screen footprint) unless size is None."""
    a = cv2.GaussianBlur(mask.astype(np.float32) / 255.0, (0, 0), 0.7)  # soft, anti-aliased edge
    premult = photo.astype(np.float32) * a[..., None]
    if size is not None:
        premult = cv2.resize(premult, size, interpolation=cv2.INTER_AREA)
        a = cv2.resize(a, size, interpolation=cv2.INTER_AREA)
    return premult, a


class _ByIdentity:
    """A cache key that hashes and compares by object identity; it holds the object, so the id
    stays unique while the key is cached."""

    __slots__ = ("obj",)

    def __init__(self, obj: object) -> None:
        self.obj = obj

    def __hash__(self) -> int:
        return id(self.obj)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _ByIdentity) and other.obj is self.obj


@functools.lru_cache(maxsize=16)
def _photo_layers_cached(photo: _ByIdentity, mask: _ByIdentity, size: tuple[int, int] | None) -> tuple[np.ndarray, np.ndarray]:
    """`_photo_layers` memoised by the photo and mask OBJECTS (render_view's fast path: the
    simulator renders the same photo every frame; the photo must not change in place)."""
    premult, a = _photo_layers(photo.obj, mask.obj, size)
    premult.flags.writeable = a.flags.writeable = False
    return premult, a


def _floater_layer(f: Floater, C: np.ndarray, d: np.ndarray, fast: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(colour h x w x 3 float32, coverage h x w float32 0..1) of one floater seen from camera
    centre C (world) along rays d (world, h x w x 3). fast: reuse the prefiltered photo of an
    earlier frame at the same on-screen size (`_photo_layers_cached`) and the inexact
    `_footprint` (equal to the exact layer up to float rounding)."""
    Tm = np.linalg.inv(f.T_world_model)
    o = Tm[:3, :3] @ C + Tm[:3, 3]
    dm = d.astype(np.float64) @ Tm[:3, :3].T
    dz = dm[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(np.abs(dz) > 1e-12, -o[2] / dz, np.nan)
        if f.bend_mm != 0.0:
            half_w = 0.5 * cv2.boundingRect(f.mask)[2] / f.alpha
            for _ in range(8):  # fixed point: z(x(s)) on the bent sheet z = -b (x / half_w)^2
                xm = o[0] + s * dm[..., 0]
                zt = -f.bend_mm * (xm / half_w) ** 2
                s = (zt - o[2]) / dz
    valid = np.isfinite(s) & (s > 0)
    xm = o[0] + s * dm[..., 0]
    ym = o[1] + s * dm[..., 1]
    u = np.where(valid, xm * f.alpha + f.origin_px[0], -1e4)
    v = np.where(valid, ym * f.alpha + f.origin_px[1], -1e4)
    H, W = f.mask.shape
    near = valid & (u > -2) & (v > -2) & (u < W + 1) & (v < H + 1)
    fp = _footprint(u, v, near, exact=not fast)
    size = None
    if fp > 1.2:  # prefilter the photo to the on-screen footprint (anti-aliasing)
        k = 1.0 / fp
        size = (max(2, round(W * k)), max(2, round(H * k)))
        sx, sy = size[0] / W, size[1] / H
        u, v = (u + 0.5) * sx - 0.5, (v + 0.5) * sy - 0.5
    premult, a = (_photo_layers_cached(_ByIdentity(f.photo), _ByIdentity(f.mask), size) if fast
                  else _photo_layers(f.photo, f.mask, size))
    mu, mv = u.astype(np.float32), v.astype(np.float32)
    cov = cv2.remap(a, mu, mv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    col = cv2.remap(premult, mu, mv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    cov = np.where(valid, cov, np.float32(0))
    col = np.where(cov[..., None] > 1e-4, col / np.maximum(cov, np.float32(1e-4))[..., None], np.float32(0))
    return col.reshape(*cov.shape, 3), np.clip(cov, 0, 1)


def _foam_layer(foam: Foam, P: np.ndarray) -> np.ndarray:
    """Foam coverage (0..1) at world water points P (H, W, 2): ragged blobs around each patch."""
    tex = _texture(foam.seed + 3, 128, 3.0)
    ragged = _sample_wrapped(tex, P[..., 0], P[..., 1], 1.5)
    cov = np.zeros(P.shape[:2], np.float32)
    for x, y, r in np.asarray(foam.patches, float).reshape(-1, 3):
        dist = np.hypot(P[..., 0] - np.float32(x), P[..., 1] - np.float32(y)) / np.float32(r)
        cov = np.maximum(cov, np.clip((1.0 - dist + 0.35 * ragged) * 4, 0, 1))
    return cov


NOISE_TILE_PAD = 64  # the pre-drawn noise tile is this many px larger than the image each way


@functools.lru_cache(maxsize=4)
def _noise_tile(height: int, width: int, sigma: float) -> np.ndarray:
    """Gaussian noise of std `sigma` (float32, (height + pad) x (width + pad) x 3), drawn once
    per image size from a fixed seed; memoised, read-only. `_apply_effects(noise_tile=True)`
    adds or subtracts a window of it at a random offset: per-pixel independent noise for ~1 %
    of the cost of drawing it afresh."""
    pad = NOISE_TILE_PAD
    tile = np.random.default_rng([height, width, 17]).standard_normal((height + pad, width + pad, 3),
                                                                       dtype=np.float32)
    tile *= np.float32(sigma)
    tile.flags.writeable = False
    return tile


def _apply_effects(img: np.ndarray, fx: CameraEffects, rng: np.random.Generator,
                   noise_tile: bool = False) -> np.ndarray:
    """CameraEffects on a float32 BGR image. noise_tile: the sensor noise is a window of
    `_noise_tile` at an offset drawn from `rng` (with a random sign) instead of fresh draws."""
    if fx.blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), fx.blur_sigma)
    gains = fx.gain * np.asarray(fx.white_balance, np.float32)
    if np.any(gains != 1):  # (a product with 1.0 would only cost time)
        img = img * gains
    if noise_tile:  # cv2 rounds and saturates to uint8 in the same pass (numpy's rint/clip: ~10x slower)
        if fx.noise_sigma > 0:
            H, W = img.shape[:2]
            oy, ox, sign = rng.integers(0, NOISE_TILE_PAD, 3)
            noise = _noise_tile(H, W, float(fx.noise_sigma))[oy:oy + H, ox:ox + W, :img.shape[2]]
            out = (cv2.add if sign % 2 else cv2.subtract)(img, noise, dtype=cv2.CV_8U)
        else:
            out = cv2.add(img, (0.0, 0.0, 0.0, 0.0), dtype=cv2.CV_8U)
    else:
        if fx.noise_sigma > 0:
            img = img + rng.normal(0, fx.noise_sigma, img.shape).astype(np.float32)
        out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if fx.jpeg_quality > 0:
        _, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(fx.jpeg_quality),
                                            cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420])
        out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    return out


def coarse_rays(rays: np.ndarray, stride: int) -> np.ndarray:
    """Camera-frame rays (ceil(H/stride), ceil(W/stride), 3) through the centres of the
    stride x stride pixel blocks of `rays` (H, W, 3; block means, cv2.INTER_AREA): the grid that
    cv2.resize (INTER_LINEAR) maps back onto the full image in render_view's fast path."""
    H, W = rays.shape[:2]
    return cv2.resize(np.ascontiguousarray(rays, np.float64), (-(-W // stride), -(-H // stride)),
                      interpolation=cv2.INTER_AREA)


def _world_rays(rays: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Unit world rays (h, w, 3 float32) of camera-frame rays (h, w, 3) for camera rotation R."""
    d = (rays @ R.T).astype(np.float32)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)  # not in place: numpy's broadcast /= is ~5x slower


def _water_hits(rays: np.ndarray, R: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(d, P, water) for camera-frame rays (h, w, 3) of a camera at rotation R, centre C
    (camera -> world, mm): unit world rays d (float32), their hits P (h, w, 2, world xy mm) on
    the water plane z = 0 and whether they hit it (rays at or above the horizon: P = C)."""
    d = _world_rays(rays, R)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(d[..., 2] < -1e-9, np.float32(-C[2]) / d[..., 2], np.float32(np.nan))
    water = np.isfinite(s) & (s > 0)
    P = C[:2].astype(np.float32) + np.where(water, s, np.float32(0))[..., None] * d[..., :2]
    return d, P, water


def render_view(scene: Scene, cam: Camera, T_world_cam: np.ndarray, t: float = 0.0,
                rng: np.random.Generator | None = None, effects: CameraEffects | None = None,
                rays: np.ndarray | None = None, compiled: bool = True, water_stride: int = 1,
                water_rays: np.ndarray | None = None) -> np.ndarray:
    """What camera `cam` at pose T_world_cam (4x4, camera -> world, mm) sees of `scene` at time
    t (s): BGR uint8 of cam.size, lens distortion included. `rng` drives the sensor noise (a
    fixed default seed when None, so renders are reproducible). `rays`: `pixel_rays(cam)`,
    precomputed when rendering many frames of one camera (see `StereoRenderer`). `compiled`:
    the water pass by the numba kernel (synthetic_kernel.py, ~10x faster) or by the numpy
    reference `_shade_water` (identical model; textures sampled without OpenCV's 1/32-texel
    weight quantisation, so the two differ by well under 1 DN on average).

    water_stride > 1 is the fast path for live simulation (~7x less CPU at 4, benchmarks/render_speed.py): the water is
    shaded on a grid of one ray per stride x stride block (`coarse_rays(rays, stride)`, or
    `water_rays` when precomputed) and upsampled bilinearly, so waves, mottle and glints keep
    their look but not their finest detail; floaters and foam are still drawn at full resolution
    (full-resolution rays only inside their image windows), and the sensor noise is a window of
    a pre-drawn noise tile at a random offset. Same rng state -> same image. water_stride = 1 is
    the exact render."""
    if int(water_stride) != water_stride or water_stride < 1:
        raise InputError(f"water_stride {water_stride!r}: must be a positive integer")
    water_stride = int(water_stride)
    T = np.asarray(T_world_cam, float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InputError("T_world_cam: expected a finite 4x4 transform")
    rng = np.random.default_rng(0) if rng is None else rng
    R, C = T[:3, :3], T[:3, 3]
    rays = pixel_rays(cam) if rays is None else rays
    fast = water_stride > 1
    rays_w = rays if not fast else coarse_rays(rays, water_stride) if water_rays is None else water_rays
    w = scene.water
    if compiled:
        from photoservo.sim import renderer_kernel as sk

        dx, dy = _ripple_slopes(w.seed)
        img, shade, P, water, d = sk.shade_water(rays_w, R, C, w.waves, t, w.ripple, dx, dy,
                                                 _texture(w.seed + 1, 128, 4.0), w.mottle, w.sun_dir,
                                                 w.colour_bgr, w.sky_bgr, w.glint)
    else:
        d, P, water = _water_hits(rays_w, R, C)
        img, shade = _shade_water(w, P, d, t)
        img = np.where(water[..., None], img, np.asarray(w.sky_bgr, np.float32))
    if fast:  # back to full resolution; per-pixel rays and hits only inside object windows
        size = (rays.shape[1], rays.shape[0])
        # glints are far brighter than white: clipped first, they blend out instead of blocky squares
        img = cv2.resize(np.minimum(img, np.float32(255)), size, interpolation=cv2.INTER_LINEAR)
        shade = cv2.resize(shade, size, interpolation=cv2.INTER_LINEAR)

    def hits(win: tuple[slice, slice]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return _water_hits(rays[win], R, C) if fast else (d[win], P[win], water[win])

    T_cam_world = np.linalg.inv(T)
    for f in (*scene.distractors, *(() if scene.target is None else (scene.target,))):
        win = _window(cam, T_cam_world, _floater_box(f))
        if win is None:
            continue
        col, cov = _floater_layer(f, C, _world_rays(rays[win], R) if fast else d[win], fast=fast)
        col = col * (0.95 + 0.12 * (shade[win] - 1.0))[..., None]  # the swell shades it too
        img[win] = img[win] * (1 - cov[..., None]) + col * cov[..., None]
    if scene.foam is not None and len(scene.foam.patches):
        for patch in np.asarray(scene.foam.patches, float).reshape(-1, 3):
            x, y, r = patch
            box = np.array([[x + a * 1.5 * r, y + b * 1.5 * r, 0.0] for a in (-1, 1) for b in (-1, 1)])
            win = _window(cam, T_cam_world, box)
            if win is None:
                continue
            _, P_win, water_win = hits(win)
            cov = _foam_layer(Foam(patch[None], scene.foam.seed), P_win) * water_win
            img[win] = img[win] * (1 - cov[..., None]) + np.float32(238) * cov[..., None]
    return _apply_effects(img.astype(np.float32, copy=False), effects or CameraEffects(), rng, noise_tile=fast)


def render_stereo(scene: Scene, rig: Rig, T_world_left: np.ndarray, t: float = 0.0,
                  rng: np.random.Generator | None = None,
                  effects: tuple[CameraEffects, CameraEffects] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Both views of a stereo rig whose left camera is at T_world_left (4x4, mm); the right
    camera follows from the rig's extrinsics (X_right = R · X_left + T)."""
    return StereoRenderer(rig).render(scene, T_world_left, t, rng, effects)


class StereoRenderer:
    """`render_stereo` for many frames of one rig: the per-pixel rays are computed once.

    >>> r = StereoRenderer(synthetic_rig())
    >>> T_world_left = make_transform(np.diag([1.0, -1.0, -1.0]), [0.0, 0.0, 1000.0])  # 1 m up, looking down
    >>> left, right = r.render(Scene(water=calm_water(0)), T_world_left, 0.0, water_stride=4)
    >>> left.shape, right.dtype
    ((480, 640, 3), dtype('uint8'))
    """

    def __init__(self, rig: Rig) -> None:
        self.rig = rig
        self.rays_left = pixel_rays(rig.left)
        self.rays_right = pixel_rays(rig.right)
        self.T_left_right = np.linalg.inv(stereo_transform(rig))
        self._water_rays: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def water_rays(self, stride: int) -> tuple[np.ndarray, np.ndarray]:
        """(left, right) `coarse_rays` for render_view's fast path at `stride`, computed once."""
        if stride not in self._water_rays:
            self._water_rays[stride] = (coarse_rays(self.rays_left, stride), coarse_rays(self.rays_right, stride))
        return self._water_rays[stride]

    def render(self, scene: Scene, T_world_left: np.ndarray, t: float = 0.0,
               rng: np.random.Generator | None = None,
               effects: tuple[CameraEffects, CameraEffects] | None = None,
               water_stride: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """(left, right) BGR images with the left camera at T_world_left (4x4, mm) at time t (s).
        water_stride > 1: render_view's fast path (coarse water, full-resolution floaters)."""
        rng = np.random.default_rng(0) if rng is None else rng
        T_world_right = np.asarray(T_world_left, float) @ self.T_left_right
        fl, fr = effects if effects is not None else (None, None)
        wl, wr = self.water_rays(water_stride) if water_stride > 1 else (None, None)
        return (render_view(scene, self.rig.left, T_world_left, t, rng, fl, self.rays_left,
                            water_stride=water_stride, water_rays=wl),
                render_view(scene, self.rig.right, T_world_right, t, rng, fr, self.rays_right,
                            water_stride=water_stride, water_rays=wr))



# ----------------------------------------------------------------------------- scene generator

EFFECTS = ("waves", "glints", "noise", "blur", "brightness", "white-balance", "chroma", "bend", "foam")
DEFAULT_EFFECTS = ("waves", "glints", "noise")


@dataclass(frozen=True)
class SynthParams:
    """[synthetic] config: ranges and strengths used by `random_scene` / `photoservo synth`."""

    distance_mm: tuple[float, float]  # range of the target's depth in the left camera (mm)
    tilt_max_deg: float  # max angle between the target's normal and the left optical axis (deg)
    length_mm: tuple[float, float]  # range of the creature's length along model x (mm)
    max_image_fraction: float  # the creature's box diagonal stays below this fraction of the image height
    calib_rotation_deg: float  # stereo rotation error of the rendering rig vs the written one (deg)
    calib_focal_pct: float  # focal length error of each rendering camera vs the written one (%)
    wave_slope: float  # RMS slope of the wind waves (rad) with "waves"
    glint: float  # sun glint strength with "glints" (0..2)
    noise_sigma: float  # sensor noise (8-bit DN) with "noise"
    blur_sigma: float  # Gaussian blur (px) with "blur"
    brightness: float  # max relative gain change (both cameras) with "brightness"
    white_balance: float  # max per-channel gain change (each camera) with "white-balance"
    jpeg_quality: int  # JPEG quality (4:2:0 chroma) with "chroma"
    bend: float  # ends lifted by this fraction of the creature's length with "bend"
    foam_cover: float  # foam patch area as a fraction of the creature's area with "foam"

    def validate(self, where: str) -> None:
        lo, hi = self.distance_mm
        if not 50 <= lo <= hi:
            raise InputError(f"config key '{where}.distance_mm': need 50 <= min <= max, got {list(self.distance_mm)}")
        lo, hi = self.length_mm
        if not 1 <= lo <= hi:
            raise InputError(f"config key '{where}.length_mm': need 1 <= min <= max, got {list(self.length_mm)}")
        if not 0 <= self.tilt_max_deg <= 75:
            raise InputError(f"config key '{where}.tilt_max_deg': must be within 0..75, got {self.tilt_max_deg}")
        if not 0.05 <= self.max_image_fraction <= 1:
            raise InputError(f"config key '{where}.max_image_fraction': must be within 0.05..1")
        if not 1 <= self.jpeg_quality <= 100:
            raise InputError(f"config key '{where}.jpeg_quality': must be within 1..100, got {self.jpeg_quality}")
        for k in ("calib_rotation_deg", "calib_focal_pct", "wave_slope", "glint", "noise_sigma",
                  "blur_sigma", "brightness", "white_balance", "bend", "foam_cover"):
            if not getattr(self, k) >= 0:
                raise InputError(f"config key '{where}.{k}': must be >= 0, got {getattr(self, k)}")
        if self.brightness >= 1 or self.white_balance >= 1:
            raise InputError(f"config key '{where}.brightness/white_balance': must be below 1")


@dataclass(frozen=True)
class SyntheticScene:
    """One generated test scene.

    left, right: the rendered images (BGR uint8). rig: the rig as written to rig.toml (what the
    estimator is told); rig_true: the rig that rendered the images (rig plus calibration error).
    truth: ground truth in the estimate-JSON shape (see `random_scene`). photo: the photo the
    estimator is given; render_photo: the photo of the creature actually floating there."""

    left: np.ndarray
    right: np.ndarray
    rig: Rig
    rig_true: Rig
    truth: dict
    photo: np.ndarray
    render_photo: np.ndarray
    scene: Scene
    T_world_left: np.ndarray


def synthetic_rig() -> Rig:
    """The rig written with synthetic scenes: 640x480, f = 800 px, 100 mm baseline, mild barrel
    distortion, slightly different right camera and a 0.5 degree toe-in, like a real calibration."""
    Kl = np.array([[800.0, 0.0, 319.5], [0.0, 800.0, 239.5], [0.0, 0.0, 1.0]])
    Kr = np.array([[804.0, 0.0, 322.1], [0.0, 803.2, 237.8], [0.0, 0.0, 1.0]])
    left = Camera((640, 480), Kl, np.array([-0.10, 0.05, 0.0, 0.0, 0.0]))
    right = Camera((640, 480), Kr, np.array([-0.095, 0.045, 0.0003, -0.0002, 0.0]))
    R, _ = cv2.Rodrigues(np.array([0.001, -np.radians(0.5), 0.0005]))
    return Rig(left=left, right=right, R=R, T=np.array([-100.0, 0.4, 0.8]))


def perturb_rig(rig: Rig, rng: np.random.Generator, rotation_deg: float, focal_pct: float) -> tuple[Rig, dict]:
    """The rig a scene is really rendered with: the written `rig` with a calibration error of
    exactly `rotation_deg` of extra stereo rotation (random axis) and each camera's focal length
    scaled by 1 ± focal_pct/100 (random sign). Returns (rig_true, description)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    dR, _ = cv2.Rodrigues(axis * np.radians(rotation_deg))
    signs = rng.choice([-1.0, 1.0], size=2)

    def cam(c: Camera, sgn: float) -> Camera:
        K = c.K.copy()
        K[0, 0] *= 1 + sgn * focal_pct / 100
        K[1, 1] *= 1 + sgn * focal_pct / 100
        return Camera(c.size, K, c.dist.copy())

    true = Rig(left=cam(rig.left, signs[0]), right=cam(rig.right, signs[1]), R=dR @ rig.R, T=rig.T.copy(),
               hand_eye=rig.hand_eye)
    return true, {"stereo_rotation_deg": float(rotation_deg), "focal_pct": [float(s * focal_pct) for s in signs]}


def _undistort_pixel(cam: Camera, p: np.ndarray) -> np.ndarray:
    crit = (cv2.TERM_CRITERIA_COUNT, 10, 0.0)  # ~1e-9 px for mild distortion; EPS checks cost 3x
    xy = cv2.undistortPointsIter(np.asarray(p, float).reshape(-1, 1, 2), cam.K, cam.dist, None, None, crit)
    return np.column_stack([xy.reshape(-1, 2), np.ones(len(xy))])


def _inside(cam: Camera, uv: np.ndarray, margin: float) -> bool:
    return bool(np.all(np.isfinite(uv)) and np.all(uv >= margin)
                and np.all(uv[:, 0] <= cam.width - 1 - margin) and np.all(uv[:, 1] <= cam.height - 1 - margin))


def _camera_pose(rng: np.random.Generator, rig: Rig, corners_model: np.ndarray, T_world_model: np.ndarray,
                 distance: float, tilt: float, tries: int = 300) -> np.ndarray | None:
    """A left-camera pose T_world_left with the model origin at depth `distance` (mm) in the left
    camera, the model normal at angle `tilt` (rad) from the left optical axis, random azimuth and
    roll, and every model corner inside both images (10 px margin). None if none fits."""
    from photoservo.vision.rig import project_points

    T_rl = stereo_transform(rig)
    P = T_world_model[:3, 3]
    n_down = T_world_model[:3, 2]  # the model normal (z), pointing into the water
    Xw = corners_model @ T_world_model[:3, :3].T + P
    for _ in range(tries):
        phi, roll = rng.uniform(0, 2 * np.pi, 2)
        # optical axis: the model normal tipped by `tilt` towards azimuth phi
        a = np.cross(n_down, [1.0, 0, 0]) if abs(n_down[0]) < 0.9 else np.cross(n_down, [0, 1.0, 0])
        a /= np.linalg.norm(a)
        b = np.cross(n_down, a)
        zc = math.cos(tilt) * n_down + math.sin(tilt) * (math.cos(phi) * a + math.sin(phi) * b)
        e = np.cross(zc, a)
        e /= np.linalg.norm(e)
        f = np.cross(zc, e)
        xc = math.cos(roll) * e + math.sin(roll) * f
        R_wc = np.column_stack([xc, np.cross(zc, xc), zc])
        cam = rig.left
        p = rng.uniform([40, 40], [cam.width - 41, cam.height - 41])
        X_cam = _undistort_pixel(cam, p)[0] * distance
        C = P - R_wc @ X_cam
        if C[2] < 50:  # the rig must be above the water
            continue
        T_wl = make_transform(R_wc, C)
        T_lw = np.linalg.inv(T_wl)
        Xl = Xw @ T_lw[:3, :3].T + T_lw[:3, 3]
        Xr = Xl @ T_rl[:3, :3].T + T_rl[:3, 3]
        if _inside(rig.left, project_points(Xl, rig.left), 10) and _inside(rig.right, project_points(Xr, rig.right), 10):
            return T_wl
    return None


def scene_truth(empty: bool, R: np.ndarray, position: np.ndarray, alpha: float, model: PhotoModel) -> dict:
    """A scene's ground truth in the estimate-JSON shape of DESIGN.md for the estimator's
    photo-model `model` at pose (R, position mm, model in the true left camera frame) and ratio
    alpha (px/mm), plus tilt_deg (angle of the model normal from the optical axis); the pose keys
    are None for empty water."""
    return {
        "found": not empty,
        "position_mm": None if empty else [float(v) for v in position],
        "rotation": None if empty else [[float(v) for v in row] for row in R],
        "alpha_px_per_mm": None if empty else float(alpha),
        "size_mm": None if empty else [float(model.size_px[0] / alpha), float(model.size_px[1] / alpha)],
        "fitness": None, "generations": None, "seconds": None,
        "tilt_deg": float(np.degrees(np.arccos(np.clip(R[2, 2], -1, 1)))),
    }


def match_individuals(model_A: PhotoModel, model_B: PhotoModel, alpha_A: float) -> tuple[float, np.ndarray]:
    """Ground truth for another individual's photo (`random_scene`'s other-photo case): the
    photo-model B of the estimator's photo laid onto creature A (photo-model A at alpha_A px/mm)
    by equal mask area in mm² (alpha_B = alpha_A · sqrt(area_B / area_A)) and coincident mask
    centroids. Returns (alpha_B px/mm, position of B's origin in A's model frame (3,) mm)."""
    def centroid(m: PhotoModel) -> np.ndarray:
        ys, xs = np.nonzero(m.mask)
        return np.array([xs.mean(), ys.mean()])

    s = math.sqrt(np.count_nonzero(model_A.mask) / np.count_nonzero(model_B.mask))  # A px per B px
    xA = centroid(model_A) + (np.array(model_B.origin_px) - centroid(model_B)) * s
    return alpha_A / s, np.array([*(xA - np.array(model_A.origin_px)) / alpha_A, 0.0])


def _buoy_photo(hue: int, rng: np.random.Generator) -> np.ndarray:
    """A 'buoy' look-alike: a shaded disc in the target's hue with a dark band, on white."""
    img = np.full((160, 160, 3), 240, np.uint8)
    hsv = np.uint8([[[hue, 200, 210]]])
    col = cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0, 0].astype(float)
    yy, xx = np.mgrid[0:160, 0:160]
    r = np.hypot(xx - 80, yy - 80)
    disc = r < 60
    shade = np.clip(1.1 - 0.5 * np.hypot(xx - 60, yy - 60) / 80, 0.5, 1.2)
    img[disc] = np.clip(col[None] * shade[disc][:, None], 0, 255).astype(np.uint8)
    band = disc & (np.abs(xx - 80 - 10 * rng.uniform(-1, 1)) < 9)
    img[band] = 60  # a dark band (a white one would join the backdrop and halve the buoy)
    return img


def random_scene(seed: int, params: SynthParams, photo_params, kind: str = "squid",
                 other_photo: bool = False, effects: tuple[str, ...] = DEFAULT_EFFECTS, empty: bool = False,
                 distractor: bool = False, distance_mm: float | None = None, tilt_deg: float | None = None,
                 photo: np.ndarray | None = None, estimator_photo: np.ndarray | None = None,
                 rig: Rig | None = None, split: bool = False) -> SyntheticScene:
    """A seeded test scene for the estimator: a creature lying face-up on water, seen by a rig.

    The creature is `photo` (default: the specimen `kind`, seed 0) at a random length in
    params.length_mm, random heading, depth `distance_mm` (default: random in
    params.distance_mm) in the left camera and tilt `tilt_deg` (default: random up to
    params.tilt_max_deg) between its normal and the left optical axis, fully inside both images.
    The images are rendered with `rig` (default `synthetic_rig()`) perturbed by the configured
    calibration error; `SyntheticScene.rig` is the unperturbed rig the estimator is told.

    other_photo: the estimator gets a photo of ANOTHER individual (`estimator_photo`, default
    the `kind` specimen with other=True) while the `photo` creature floats in the scene.
    empty: no creature (truth found=false). distractor: add a look-alike (another species, a
    recoloured copy of the creature, or a buoy in the creature's hue) elsewhere in view.
    effects: a subset of EFFECTS, magnitudes from `params`.
    split: a band of foam across the creature (perpendicular to its longer box side, 10-18 % of
    that side wide, centred within the middle 40 %), cutting its hue region in two (drawn from a
    random stream of its own: the rest of the scene is the same as without it).

    Ground truth (`truth`, the estimate JSON of DESIGN.md plus extra keys), in the TRUE left
    camera frame, for the photo-model the estimator builds from ITS photo with `photo_params`:
      rotation, position_mm: X_left = R · X_model + position, for that model's frame;
      alpha_px_per_mm: px of the estimator's photo per mm of the floating creature;
      size_mm: that model's size_px / alpha.
    Same photo: exact. Other photo: the two individuals are matched by their masks — equal area
    in mm² (alpha_B = alpha_A · sqrt(area_B / area_A)) and coincident mask centroids — so
    position_mm is where model B's origin (its box centre) lands on the creature, and size_mm is
    B's box at that scale (on the shipped specimens this matching is within 4 % in scale and
    2 px of the best-overlap (IoU) alignment). creature_size_mm is the floating creature's own
    box size (mm). With "bend", the truth is the flat model tangent to the bent body at its
    origin; the ends rise towards the camera by params.bend x length.
    Extra keys: distance_mm (depth of the creature's model origin), tilt_deg, same_photo,
    creature_size_mm, calibration_error, effects, distractors, split, seed."""
    from photoservo.vision.photo_model import build_photo_model
    from photoservo.sim.specimens import specimen

    if photo is not None and other_photo and estimator_photo is None:
        raise InputError("other_photo with a given photo needs the other individual's estimator_photo")
    bad = [e for e in effects if e not in EFFECTS]
    if bad:
        raise InputError(f"effect '{bad[0]}': unknown, choose from {', '.join(EFFECTS)}")
    rng = np.random.default_rng([int(seed), 2024])
    rig = synthetic_rig() if rig is None else rig
    rig_true, calib = perturb_rig(rig, rng, params.calib_rotation_deg, params.calib_focal_pct)
    renderer = StereoRenderer(rig_true)
    render_photo = specimen(kind, 0) if photo is None else photo
    if estimator_photo is None:
        estimator_photo = specimen(kind, 0, other=True) if other_photo else render_photo
    same = estimator_photo is render_photo
    model_A = build_photo_model(render_photo, photo_params)
    model_B = model_A if same else build_photo_model(estimator_photo, photo_params)
    fx = set(effects)
    water = calm_water(int(rng.integers(1 << 30)), wave_slope=params.wave_slope if "waves" in fx else 0.0,
                       glint=params.glint if "glints" in fx else 0.0)
    if "waves" not in fx:
        water = Water(**{**water.__dict__, "ripple": 0.0})
    dist = float(rng.uniform(*params.distance_mm)) if distance_mm is None else float(distance_mm)
    tilt = float(np.radians(rng.uniform(0, params.tilt_max_deg) if tilt_deg is None else tilt_deg))
    heading = float(rng.uniform(-np.pi, np.pi))
    wA, hA = model_A.size_px
    length = float(rng.uniform(*params.length_mm))
    cam = rig_true.left
    # keep the creature's box diagonal below max_image_fraction of the image height
    limit = params.max_image_fraction * cam.height * dist / cam.K[1, 1] / math.hypot(1, hA / wA)
    length = min(length, limit)
    T_world_model = lying_on_water([0.0, 0.0, 0.0], heading)
    T_world_left = None
    for _ in range(8):
        alpha_A = wA / length
        corners = np.array([[-wA / 2, -hA / 2, 0], [wA / 2, -hA / 2, 0], [wA / 2, hA / 2, 0], [-wA / 2, hA / 2, 0]]) / alpha_A
        T_world_left = _camera_pose(rng, rig_true, corners, T_world_model, dist, tilt)
        if T_world_left is not None:
            break
        length *= 0.8
    if T_world_left is None:
        raise InputError(f"synthetic scene: cannot fit the creature in both images at {dist:.0f} mm and tilt "
                         f"{np.degrees(tilt):.0f} deg")
    bend = params.bend * length if "bend" in fx else 0.0
    target = floater_from_model(render_photo, model_A, alpha_A, T_world_model, bend_mm=bend)
    T_left_world = np.linalg.inv(T_world_left)
    # sun near the mirror direction of the central view ray, so glints land in or near view
    zc = T_world_left[:3, 2]
    mirror = np.array([-zc[0], -zc[1], -zc[2]]) * np.array([-1, -1, 1])
    off = rng.normal(0, np.radians(12), 3)
    sun = mirror + off
    sun[2] = abs(sun[2]) + 0.2
    water = Water(**{**water.__dict__, "sun_dir": tuple(sun / np.linalg.norm(sun))})
    # look-alike distractor on the water, away from the creature, inside the left view
    distractors: list[Floater] = []
    dinfo: list[dict] = []
    if distractor:
        choice = ["species", "recolour", "buoy"][int(rng.integers(3))]
        if choice == "species":
            dphoto = specimen([k for k in ("squid", "crab", "fish") if k != kind][int(rng.integers(2))], 0)
        elif choice == "recolour":  # the same shape in another colour, never the water's (~100)
            dom = int(np.argmax(np.bincount(model_A.inner_hue, minlength=180)))
            shifts = [k for k in range(40, 141, 5) if hue_distance(dom + k, 100) > 30 and hue_distance(k, 0) >= 40]
            hsv = cv2.cvtColor(render_photo, cv2.COLOR_BGR2HSV)
            hsv[..., 0] = ((hsv[..., 0].astype(int) + int(rng.choice(shifts))) % 180).astype(np.uint8)
            dphoto = cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)
        else:
            dom = np.bincount(model_A.inner_hue, minlength=180)
            dphoto = _buoy_photo(int(np.argmax(dom)), rng)
        dmodel = build_photo_model(dphoto, photo_params)
        d_alpha = dmodel.size_px[0] / (length * (0.5 if choice == "buoy" else rng.uniform(0.8, 1.2)))
        rays = renderer.rays_left
        R_wl, C = T_world_left[:3, :3], T_world_left[:3, 3]
        for _ in range(200):
            p = rng.uniform([40, 40], [cam.width - 41, cam.height - 41]).astype(int)
            dw = R_wl @ rays[p[1], p[0]]
            if dw[2] >= -1e-6:
                continue
            Pw = C + (-C[2] / dw[2]) * dw
            if np.hypot(*Pw[:2]) > 1.3 * length:
                T_d = lying_on_water(Pw, float(rng.uniform(-np.pi, np.pi)))
                distractors.append(floater_from_model(dphoto, dmodel, d_alpha, T_d))
                dinfo.append({"kind": choice, "position_mm": [float(v) for v in (T_left_world @ T_d)[:3, 3]]})
                break
    foam = None
    if "foam" in fx:
        area_mm2 = float(np.count_nonzero(model_A.mask)) / alpha_A**2
        ys, xs = np.nonzero(model_A.mask)
        i = int(rng.integers(len(xs)))
        pm = np.array([(xs[i] - model_A.origin_px[0]) / alpha_A, (ys[i] - model_A.origin_px[1]) / alpha_A, 0.0])
        pw = T_world_model[:3, :3] @ pm + T_world_model[:3, 3]
        patches = [[pw[0], pw[1], math.sqrt(params.foam_cover * area_mm2 / math.pi)]]
        for _ in range(3):  # a few more patches scattered around
            q = rng.normal(0, 1.5 * length, 2)
            patches.append([q[0], q[1], rng.uniform(0.05, 0.2) * length])
        foam = Foam(np.array(patches), seed=int(rng.integers(1 << 30)))
    if split:
        band_rng = np.random.default_rng([int(seed), 77])
        w_mm, h_mm = wA / alpha_A, hA / alpha_A
        long_, short = max(w_mm, h_mm), min(w_mm, h_mm)
        at = band_rng.uniform(-0.2, 0.2) * long_
        r = band_rng.uniform(0.05, 0.09) * long_  # patch radius: the band is about 2 r wide
        band = []
        for across in np.arange(-0.75 * short, 0.75 * short + 1e-9, 0.8 * r):
            pm = np.array([at, across, 0.0] if w_mm >= h_mm else [across, at, 0.0])
            pw = T_world_model[:3, :3] @ pm + T_world_model[:3, 3]
            band.append([pw[0], pw[1], r])
        old = np.zeros((0, 3)) if foam is None else foam.patches
        foam = Foam(np.vstack([old, band]), seed=int(band_rng.integers(1 << 30)) if foam is None else foam.seed)
    scene = Scene(water=water, target=None if empty else target, distractors=tuple(distractors), foam=foam)
    # per-camera effects
    gain = 1 + (rng.uniform(-params.brightness, params.brightness) if "brightness" in fx else 0.0)
    cam_fx = []
    for _ in range(2):
        wb = tuple(1 + rng.uniform(-params.white_balance, params.white_balance, 3)) if "white-balance" in fx else (1.0, 1.0, 1.0)
        cam_fx.append(CameraEffects(blur_sigma=params.blur_sigma if "blur" in fx else 0.0, gain=gain,
                                    white_balance=tuple(float(v) for v in wb),
                                    noise_sigma=params.noise_sigma if "noise" in fx else 0.0,
                                    jpeg_quality=params.jpeg_quality if "chroma" in fx else 0))
    left, right = renderer.render(scene, T_world_left, 0.0, rng, (cam_fx[0], cam_fx[1]))
    # ground truth for the estimator's photo-model (see docstring)
    T_left_model = T_left_world @ T_world_model
    R = T_left_model[:3, :3]
    alpha, origin_mm = (alpha_A, np.zeros(3)) if same else match_individuals(model_A, model_B, alpha_A)
    position = R @ origin_mm + T_left_model[:3, 3]
    truth = {
        **scene_truth(empty, R, position, alpha, model_B),
        "distance_mm": float(T_left_model[2, 3]),
        "same_photo": bool(same),
        "creature_size_mm": [float(wA / alpha_A), float(hA / alpha_A)],
        "calibration_error": calib,
        "effects": sorted(fx),
        "distractors": dinfo,
        "split": bool(split),
        "seed": int(seed),
    }
    return SyntheticScene(left=left, right=right, rig=rig, rig_true=rig_true, truth=truth, photo=estimator_photo,
                          render_photo=render_photo, scene=scene, T_world_left=T_world_left)
