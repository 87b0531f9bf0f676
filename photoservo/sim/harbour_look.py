"""Water, occluders and light of the second scene generator (`sim/harbour.py`), and the camera
image of a harbour scene: a spectral height field (power law with a wind direction, two scales)
shading a turbid body colour mixed by Schlick's Fresnel with a sky gradient and clouds, sun
glitter; foam patches and bands with ragged, bubbly edges; floating leaves and twigs; creatures
lit by the sun as curved bodies (Lambert, sky fill, Blinn-Phong highlights on the wet body); then
colour cast, per-camera white balance, vignetting, blur and sensor noise. Independent of
`sim/renderer.py` (it shares only the camera rays, `pixel_rays`).

Frames: world mm, z up, the water plane z = 0; cameras OpenCV; creatures in the model frame of
DESIGN.md (photo px (u, v) at ((u - ox)/alpha, (v - oy)/alpha, 0) mm, z into the photo).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from photoservo.sim.creatures import PHOTO_SIZE, Creature, height_slopes
from photoservo.sim.renderer import pixel_rays
from photoservo.vision.rig import Camera


@dataclass(frozen=True)
class Light:
    """Sun and sensor: sun_dir (world, towards the sun), gain (0.75-1.15), cast (B, G, R gains of
    the scene's light), per-camera white balance, noise sigma (DN), blur sigma (px)."""

    sun_dir: np.ndarray
    gain: float
    cast: np.ndarray
    white_balance: tuple[np.ndarray, np.ndarray]
    noise: float
    blur: float


@dataclass(frozen=True)
class HarbourWater:
    """Water: body colour (BGR, seen straight down), sky zenith / horizon colours, RMS slope of
    the spectral waves, wind direction (rad), glitter strength, texture seed."""

    body_bgr: np.ndarray
    zenith_bgr: np.ndarray
    horizon_bgr: np.ndarray
    slope: float
    wind: float
    glitter: float
    seed: int


@dataclass(frozen=True)
class Placed:
    """A creature on the water: T_world_model (4x4, model frame of DESIGN.md), alpha (photo px per
    mm), origin_px of its model frame in the photo, relief (photo px of body height)."""

    creature: Creature
    T_world_model: np.ndarray
    alpha: float
    origin_px: tuple[float, float]
    relief: float


@dataclass(frozen=True)
class FoamBand:
    """A foam band on the water: centre (x, y) mm, direction (rad), half-width mm, length mm."""

    centre: tuple[float, float]
    direction: float
    half_width: float
    length: float


@dataclass(frozen=True)
class HarbourScene:
    """What the cameras see: water, the target (or None), look-alikes, foam patches (rows x, y,
    radius mm), foam bands, debris (rows x, y, length mm, width mm, angle rad, kind 0 leaf /
    1 twig), light; coverage once rendered."""

    water: HarbourWater
    target: Placed | None
    distractors: tuple[Placed, ...]
    patches: np.ndarray
    bands: tuple[FoamBand, ...]
    debris: np.ndarray
    light: Light
    seed: int
    coverage: tuple[np.ndarray, np.ndarray] | None = None  # the target's visible coverage (0..1) in the
    # rendered left and right images, after foam and debris (set by random_scene)


def _spectral_slopes(seed: int, size: int, wind: float) -> tuple[np.ndarray, np.ndarray]:
    """Slopes (d/dx, d/dy per texel, unit RMS together) of a tileable height field with a power-law
    spectrum k^-3.5 spread about the wind direction (cos² spreading)."""
    rng = np.random.default_rng([seed, 33])
    k = np.fft.fftfreq(size)
    kx, ky = np.meshgrid(k, k)
    kk = np.hypot(kx, ky)
    kk[0, 0] = 1.0
    spread = 0.3 + np.cos(np.arctan2(ky, kx) - wind) ** 2
    amp = kk ** -1.75 * spread * (kk > 1.5 / size)
    spec = amp * (rng.standard_normal((size, size)) + 1j * rng.standard_normal((size, size)))
    gx = np.real(np.fft.ifft2(spec * 2j * np.pi * kx)).astype(np.float32)
    gy = np.real(np.fft.ifft2(spec * 2j * np.pi * ky)).astype(np.float32)
    rms = float(np.sqrt(np.mean(gx ** 2 + gy ** 2))) + 1e-12
    return gx / rms, gy / rms


def _wrap_sample(tex: np.ndarray, x: np.ndarray, y: np.ndarray, mm_per_texel: float) -> np.ndarray:
    return cv2.remap(tex, (x / mm_per_texel).astype(np.float32), (y / mm_per_texel).astype(np.float32),
                     cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)


def _water_colour(w: HarbourWater, P: np.ndarray, d: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """Colour of the water (float32 BGR) at world points P (h, w, 2) seen along unit rays d."""
    gx = np.zeros(P.shape[:2], np.float32)
    gy = np.zeros_like(gx)
    for size, mm, share in ((256, 9.0, 0.8), (128, 2.5, 0.45)):
        sx, sy = _spectral_slopes(w.seed + size, size, w.wind)
        gx += np.float32(w.slope * share) * _wrap_sample(sx, P[..., 0], P[..., 1], mm)
        gy += np.float32(w.slope * share) * _wrap_sample(sy, P[..., 0], P[..., 1], mm)
    n = np.dstack([-gx, -gy, np.ones_like(gx)])
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    dn = np.sum(d * n, axis=2)
    cos_v = np.clip(-dn, 0, 1)
    fres = 0.02 + 0.98 * (1 - cos_v) ** 5
    r = d - 2 * dn[..., None] * n
    elev = np.clip(r[..., 2], 0, 1) ** 0.6
    sky = w.horizon_bgr * (1 - elev[..., None]) + w.zenith_bgr * elev[..., None]
    tex_rng = np.random.default_rng([w.seed, 8])
    clouds = cv2.GaussianBlur(tex_rng.standard_normal((64, 64)).astype(np.float32), (0, 0), 4)
    clouds = (clouds - clouds.mean()) / (clouds.std() + 1e-6)
    cu = r[..., 0] / np.maximum(r[..., 2], 0.05) * 20
    cv = r[..., 1] / np.maximum(r[..., 2], 0.05) * 20
    cl = np.clip(_wrap_sample(clouds, cu, cv, 1.0) * 0.5, 0, 1)[..., None]
    sky = sky * (1 - cl) + np.float32(245) * cl
    turb = 1 + 0.1 * _wrap_sample(cv2.GaussianBlur(tex_rng.standard_normal((64, 64)).astype(np.float32), (0, 0), 6)
                                  * 8, P[..., 0], P[..., 1], 60.0)
    up = np.clip(1 + 4 * (n @ sun - sun[2]), 0.65, 1.35)  # facets turned to the sun look brighter
    col = w.body_bgr * (turb * up * (1 - fres))[..., None] + sky * fres[..., None]
    glit = np.clip(r @ sun, 0, 1) ** 1500 * (1500 * w.glitter)
    return (col + glit[..., None]).astype(np.float32)


def _foam_alpha(scene: HarbourScene, P: np.ndarray) -> np.ndarray:
    """Foam opacity (0..1) at world water points P (h, w, 2): patches and bands with ragged edges,
    bubbles thinning the margins."""
    rng = np.random.default_rng([scene.seed, 21])
    rag = cv2.GaussianBlur(rng.standard_normal((128, 128)).astype(np.float32), (0, 0), 2.5)
    rag = _wrap_sample(rag / (rag.std() + 1e-6), P[..., 0], P[..., 1], 2.0)
    bub = _wrap_sample(rng.random((64, 64)).astype(np.float32), P[..., 0], P[..., 1], 1.2)
    edge = np.full(P.shape[:2], -np.inf, np.float32)
    for x, y, r in scene.patches.reshape(-1, 3):
        edge = np.maximum(edge, 1 - np.hypot(P[..., 0] - x, P[..., 1] - y) / r)
    for b in scene.bands:
        dx, dy = P[..., 0] - b.centre[0], P[..., 1] - b.centre[1]
        c, s = math.cos(b.direction), math.sin(b.direction)
        along, across = dx * c + dy * s, -dx * s + dy * c
        inside = 1 - np.abs(across) / b.half_width
        edge = np.maximum(edge, np.where(np.abs(along) < b.length / 2, inside, -np.inf))
    a = np.clip((edge + 0.25 * rag) * 5, 0, 1)
    return (a * np.where(a < 1, 0.6 + 0.4 * bub, 1.0)).astype(np.float32)


def _debris(scene: HarbourScene, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Colour and opacity of floating debris at world points P: leaves (dull brown-olive ellipses)
    and twigs (thin dark sticks)."""
    col = np.zeros((*P.shape[:2], 3), np.float32)
    alpha = np.zeros(P.shape[:2], np.float32)
    for x, y, length, width, ang, kind in scene.debris.reshape(-1, 6):
        c, s = math.cos(ang), math.sin(ang)
        dx, dy = P[..., 0] - x, P[..., 1] - y
        u, v = (dx * c + dy * s) / (length / 2), (-dx * s + dy * c) / (width / 2)
        a = np.clip((1 - (u * u + v * v)) * 6, 0, 1) if kind == 0 else \
            np.clip((1 - np.maximum(np.abs(u), np.abs(v))) * 4, 0, 1)
        rgb = (40.0, 75.0, 95.0) if kind == 0 else (30.0, 45.0, 60.0)
        col = np.where(a[..., None] > alpha[..., None], np.array(rgb, np.float32), col)
        alpha = np.maximum(alpha, a)
    return col, alpha


def _creature_layer(p: Placed, C: np.ndarray, d: np.ndarray, P: np.ndarray, light: Light
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(colour, coverage) of a placed creature seen from camera centre C along unit world rays d
    hitting the water plane at P: its layers sampled at the model point of each ray (anti-aliased
    by an area-resampled copy at the on-screen footprint), lit by the sun, a sky fill and
    Blinn-Phong highlights."""
    T = np.linalg.inv(p.T_world_model)
    Pw = np.dstack([P, np.zeros(P.shape[:2], np.float32)])
    Xm = Pw @ T[:3, :3].T.astype(np.float32) + T[:3, 3].astype(np.float32)
    u = Xm[..., 0] * p.alpha + p.origin_px[0]
    v = Xm[..., 1] * p.alpha + p.origin_px[1]
    c = p.creature
    hx, hy = height_slopes(c, p.relief)
    layers_a = np.dstack([c.albedo * c.cover[..., None], c.cover])
    layers_b = np.dstack([hx, hy, c.gloss * c.cover])
    # footprint: photo px per image px at the creature (from the map's gradient)
    du = np.hypot(*np.gradient(u)) if min(u.shape) > 1 else np.ones_like(u)
    m = (u > 0) & (v > 0) & (u < PHOTO_SIZE[0]) & (v < PHOTO_SIZE[1])
    fp = float(np.median(du[m])) if m.any() else 1.0
    if fp > 1.3:
        size = (max(4, round(PHOTO_SIZE[0] / fp)), max(4, round(PHOTO_SIZE[1] / fp)))
        layers_a = cv2.resize(layers_a, size, interpolation=cv2.INTER_AREA)
        layers_b = cv2.resize(layers_b, size, interpolation=cv2.INTER_AREA)
        u = (u + 0.5) * (size[0] / PHOTO_SIZE[0]) - 0.5
        v = (v + 0.5) * (size[1] / PHOTO_SIZE[1]) - 0.5
        layers_b[..., :2] *= fp
    mu, mv = u.astype(np.float32), v.astype(np.float32)
    A = cv2.remap(layers_a, mu, mv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    B = cv2.remap(layers_b, mu, mv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    cov = np.clip(A[..., 3], 0, 1)
    inv = np.where(cov > 1e-3, 1 / np.maximum(cov, 1e-3), 0).astype(np.float32)
    albedo = A[..., :3] * inv[..., None]
    gloss = B[..., 2] * inv
    # normal in the model frame (body height along -z_model), then world
    nm = np.dstack([-B[..., 0], -B[..., 1], -np.ones_like(cov)])
    n = nm @ p.T_world_model[:3, :3].T.astype(np.float32)
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    sun = light.sun_dir.astype(np.float32)
    lam = np.clip(n @ sun, 0, 1)
    fill = 0.3 + 0.15 * n[..., 2]
    h = sun[None, None] - d
    h /= np.linalg.norm(h, axis=2, keepdims=True)
    spec = gloss * np.clip(np.sum(n * h, axis=2), 0, 1) ** 70 * 260
    col = albedo * (fill + 0.75 * lam)[..., None] + spec[..., None]
    return col.astype(np.float32), cov


def render_camera(scene: HarbourScene, cam: Camera, T_world_cam: np.ndarray, white_balance: np.ndarray,
                  rng: np.random.Generator) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """One camera's image (BGR uint8) of the scene at T_world_cam (4x4, camera -> world, mm) and
    the target's coverage (float32 0..1; zeros without a target): (visible after foam and debris,
    whole)."""
    R, C = T_world_cam[:3, :3], T_world_cam[:3, 3]
    d = (pixel_rays(cam) @ R.T).astype(np.float32)
    d /= np.linalg.norm(d, axis=2, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(d[..., 2] < -1e-6, -C[2] / d[..., 2], 0).astype(np.float32)
    P = C[:2].astype(np.float32) + s[..., None] * d[..., :2]
    light = scene.light
    sun = light.sun_dir.astype(np.float32)
    img = _water_colour(scene.water, P, d, sun)
    target_cov = np.zeros(P.shape[:2], np.float32)
    for p in (*scene.distractors, *(() if scene.target is None else (scene.target,))):
        col, cov = _creature_layer(p, C, d, P, light)
        img = img * (1 - cov[..., None]) + col * cov[..., None]
        if p is scene.target:
            target_cov = cov
    dcol, da = _debris(scene, P)
    img = img * (1 - da[..., None]) + dcol * da[..., None]
    fa = _foam_alpha(scene, P)
    foam_col = np.float32(236) * (0.92 + 0.08 * np.clip(sun[2], 0, 1))
    img = img * (1 - fa[..., None]) + foam_col * fa[..., None]
    visible = target_cov * (1 - fa) * (1 - da)
    # light and sensor
    img = img * (light.gain * light.cast * white_balance).astype(np.float32)
    Hh, Ww = img.shape[:2]
    yy, xx = np.mgrid[0:Hh, 0:Ww].astype(np.float32)
    r2 = ((xx - Ww / 2) ** 2 + (yy - Hh / 2) ** 2) / (0.5 * math.hypot(Ww, Hh)) ** 2
    img = img * (1 - 0.18 * r2)[..., None]
    img = cv2.GaussianBlur(img, (0, 0), light.blur)
    img = img + rng.normal(0, light.noise, img.shape).astype(np.float32)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8), (visible, target_cov)

