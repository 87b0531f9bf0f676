"""Synthetic stereo views of a photo's target floating on water (issue 2, item 7).

This module renders from camera poses it is GIVEN (DESIGN.md): it never knows about the arm.
The arm simulator (servo/world.py) and the scene generator `random_scene` hand it poses.

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
  SynthParams                            [synthetic] config section
  random_scene(seed, params, ...) -> SyntheticScene   images, rig written, rig used, truth JSON

Rendering: every pixel of the (distorted) image is undistorted to a ray (cv2.undistortPointsIter,
so the camera's lens distortion is honoured exactly), the ray is intersected with the water plane
and with each floater's surface (plane, or a gently bent sheet solved by fixed-point iteration),
and the photo is sampled there with premultiplied-alpha bilinear lookup from a photo prefiltered
to the on-screen footprint (anti-aliased edges, no backdrop fringe).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.vision.photo_model import PhotoModel
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


def make_transform(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform from rotation R (3x3) and translation t (3,)."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def lying_on_water(position_world: np.ndarray, heading: float) -> np.ndarray:
    """T_world_model of a creature lying face-up on the water at `position_world` (mm), its model
    x axis at `heading` (rad, about world z from world x). The model z axis points down."""
    R = rot_z(heading) @ np.diag([1.0, -1.0, -1.0])
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
    image: the inverse of `project_points` (iterative undistortion to 1e-10)."""
    W, H = cam.size
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    pts = np.stack([u, v], -1).reshape(-1, 1, 2)
    if np.any(cam.dist):
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)
        xy = cv2.undistortPointsIter(pts, cam.K, cam.dist, None, None, crit).reshape(H, W, 2)
    else:
        xy = np.stack([(u - cam.K[0, 2]) / cam.K[0, 0], (v - cam.K[1, 2]) / cam.K[1, 1]], -1)
    return np.concatenate([xy, np.ones((H, W, 1))], axis=-1)


def _texture(seed: int, size: int, cell: float) -> np.ndarray:
    """Tileable smooth noise (float32, size x size, zero mean, unit std)."""
    rng = np.random.default_rng([seed, int(cell * 10)])
    f = np.fft.fft2(rng.standard_normal((size, size)))
    k = np.fft.fftfreq(size)
    kk = np.hypot(*np.meshgrid(k, k))
    f *= np.exp(-(kk * cell) ** 2 * 4)
    t = np.real(np.fft.ifft2(f)).astype(np.float32)
    return (t - t.mean()) / (t.std() + 1e-9)


def _sample_wrapped(tex: np.ndarray, x: np.ndarray, y: np.ndarray, mm_per_texel: float) -> np.ndarray:
    return cv2.remap(tex, (x / mm_per_texel).astype(np.float32), (y / mm_per_texel).astype(np.float32),
                     cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)


def _shade_water(w: Water, P: np.ndarray, d: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Colour (H, W, 3 float, BGR 0..255) of the water at world points P (H, W, 2) seen along unit
    view rays d (H, W, 3): Fresnel mix of body colour and sky, mottling, sun glints. Also returns
    a shading factor (H, W) that floaters riding the same waves share."""
    x, y = P[..., 0], P[..., 1]
    gx = np.zeros_like(x)
    gy = np.zeros_like(x)
    for kx, ky, a, ph in w.waves:
        omega = math.sqrt(G_MM_S2 * math.hypot(kx, ky))
        c = a * np.cos(kx * x + ky * y - omega * t + ph)
        gx += c * kx
        gy += c * ky
    if w.ripple > 0:
        tex = _texture(w.seed, 256, 3.0)
        dx = cv2.Sobel(tex, cv2.CV_32F, 1, 0, ksize=3) / 8
        dy = cv2.Sobel(tex, cv2.CV_32F, 0, 1, ksize=3) / 8
        drift = 20.0 * t  # ripples drift with the wind (mm/s)
        gx += w.ripple * _sample_wrapped(dx, x + drift, y, 2.0)
        gy += w.ripple * _sample_wrapped(dy, x + drift, y, 2.0)
    n = np.stack([-gx, -gy, np.ones_like(x)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    cos_v = np.clip(-(d * n).sum(-1), 0.0, 1.0)
    fres = 0.02 + 0.98 * (1 - cos_v) ** 5
    sun = np.asarray(w.sun_dir)
    # light-field shading: facets tipped towards the sun are brighter (exaggerated, as the
    # sky's brightness gradient does on real water)
    shade = np.clip(1.0 + 2.5 * (gx * sun[0] + gy * sun[1]) / max(1e-6, math.hypot(sun[0], sun[1])), 0.6, 1.4)
    mott = 1 + w.mottle * _sample_wrapped(_texture(w.seed + 1, 128, 4.0), x, y, 40.0)
    body = np.asarray(w.colour_bgr, np.float32) * (shade * mott)[..., None]
    col = body * (1 - fres)[..., None] + np.asarray(w.sky_bgr, np.float32) * fres[..., None]
    if w.glint > 0:
        r = d - 2 * (d * n).sum(-1, keepdims=True) * n
        spec = np.clip(r @ sun, 0, 1) ** 600
        col += (w.glint * 900 * spec)[..., None]
    return col, shade


def _footprint(u: np.ndarray, v: np.ndarray, valid: np.ndarray) -> float:
    """Median photo pixels per image pixel over `valid` (from the map's finite differences)."""
    du = np.hypot(np.diff(u, axis=1)[:-1], np.diff(v, axis=1)[:-1])
    dv = np.hypot(np.diff(u, axis=0)[:, :-1], np.diff(v, axis=0)[:, :-1])
    m = valid[:-1, :-1] & valid[1:, :-1] & valid[:-1, 1:]
    if not m.any():
        return 1.0
    return float(np.median(np.maximum(du[m], dv[m])))


def _floater_layer(f: Floater, C: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(colour H x W x 3 float, coverage H x W float 0..1) of one floater seen from camera
    centre C (world) along rays d (world, H x W x 3)."""
    Tm = np.linalg.inv(f.T_world_model)
    o = Tm[:3, :3] @ C + Tm[:3, 3]
    dm = d @ Tm[:3, :3].T
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
    fp = _footprint(u, v, near)
    a = cv2.GaussianBlur(f.mask.astype(np.float32) / 255.0, (0, 0), 0.7)  # soft, anti-aliased edge
    premult = f.photo.astype(np.float32) * a[..., None]
    if fp > 1.2:  # prefilter the photo to the on-screen footprint (anti-aliasing)
        k = 1.0 / fp
        size = (max(2, round(W * k)), max(2, round(H * k)))
        premult = cv2.resize(premult, size, interpolation=cv2.INTER_AREA)
        a = cv2.resize(a, size, interpolation=cv2.INTER_AREA)
        sx, sy = size[0] / W, size[1] / H
        u, v = (u + 0.5) * sx - 0.5, (v + 0.5) * sy - 0.5
    mu, mv = u.astype(np.float32), v.astype(np.float32)
    cov = cv2.remap(a, mu, mv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    col = cv2.remap(premult, mu, mv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    cov = np.where(valid, cov, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        col = np.where(cov[..., None] > 1e-4, col / cov[..., None], 0.0)
    return col, np.clip(cov, 0, 1)


def _foam_layer(foam: Foam, P: np.ndarray) -> np.ndarray:
    """Foam coverage (0..1) at world water points P (H, W, 2): ragged blobs around each patch."""
    tex = _texture(foam.seed + 3, 128, 3.0)
    ragged = _sample_wrapped(tex, P[..., 0], P[..., 1], 1.5)
    cov = np.zeros(P.shape[:2], np.float32)
    for x, y, r in np.asarray(foam.patches, float).reshape(-1, 3):
        dist = np.hypot(P[..., 0] - x, P[..., 1] - y) / r
        cov = np.maximum(cov, np.clip((1.0 - dist + 0.35 * ragged) * 4, 0, 1))
    return cov


def _apply_effects(img: np.ndarray, fx: CameraEffects, rng: np.random.Generator) -> np.ndarray:
    if fx.blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), fx.blur_sigma)
    img = img * (fx.gain * np.asarray(fx.white_balance, np.float32))
    if fx.noise_sigma > 0:
        img = img + rng.normal(0, fx.noise_sigma, img.shape).astype(np.float32)
    out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if fx.jpeg_quality > 0:
        _, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(fx.jpeg_quality),
                                             cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420])
        out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    return out


def render_view(scene: Scene, cam: Camera, T_world_cam: np.ndarray, t: float = 0.0,
                rng: np.random.Generator | None = None, effects: CameraEffects | None = None) -> np.ndarray:
    """What camera `cam` at pose T_world_cam (4x4, camera -> world, mm) sees of `scene` at time
    t (s): BGR uint8 of cam.size, lens distortion included. `rng` drives the sensor noise (a
    fixed default seed when None, so renders are reproducible)."""
    T = np.asarray(T_world_cam, float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InputError("T_world_cam: expected a finite 4x4 transform")
    rng = np.random.default_rng(0) if rng is None else rng
    R, C = T[:3, :3], T[:3, 3]
    d = pixel_rays(cam) @ R.T
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(d[..., 2] < -1e-9, -C[2] / d[..., 2], np.nan)
    water = np.isfinite(s) & (s > 0)
    P = C[:2] + np.where(water, s, 0)[..., None] * d[..., :2]
    img, shade = _shade_water(scene.water, P, d, t)
    img = np.where(water[..., None], img, np.asarray(scene.water.sky_bgr, np.float32))
    for f in (*scene.distractors, *(() if scene.target is None else (scene.target,))):
        col, cov = _floater_layer(f, C, d)
        col = col * (0.95 + 0.12 * (shade - 1.0))[..., None]  # the swell shades it too
        img = img * (1 - cov[..., None]) + col * cov[..., None]
    if scene.foam is not None and len(scene.foam.patches):
        cov = _foam_layer(scene.foam, P) * water
        img = img * (1 - cov[..., None]) + np.float32(238) * cov[..., None]
    return _apply_effects(img.astype(np.float32), effects or CameraEffects(), rng)


def render_stereo(scene: Scene, rig: Rig, T_world_left: np.ndarray, t: float = 0.0,
                  rng: np.random.Generator | None = None,
                  effects: tuple[CameraEffects, CameraEffects] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Both views of a stereo rig whose left camera is at T_world_left (4x4, mm); the right
    camera follows from the rig's extrinsics (X_right = R · X_left + T)."""
    rng = np.random.default_rng(0) if rng is None else rng
    T_world_right = np.asarray(T_world_left, float) @ np.linalg.inv(stereo_transform(rig))
    fl, fr = effects if effects is not None else (None, None)
    return (render_view(scene, rig.left, T_world_left, t, rng, fl),
            render_view(scene, rig.right, T_world_right, t, rng, fr))


__all__ = [
    "CameraEffects", "Floater", "Foam", "Scene", "Water", "calm_water", "floater_from_model",
    "lying_on_water", "make_transform", "pixel_rays", "render_stereo", "render_view", "rot_z",
    "stereo_transform",
]
