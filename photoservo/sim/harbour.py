"""The second scene generator ("harbour"): stereo test scenes drawn independently of the first
renderer (`sim/renderer.py`), so that a tuning step made on one is checked on the other
(issue 9). It shares only the rig (`synthetic_rig`, `perturb_rig`), the per-pixel camera rays
(`pixel_rays`), the other-individual matching of the ground truth (`match_individuals`) and the
photo-model builder; creatures, water, occluders and light are its own:

* Creatures are procedural bodies (`draw_creature`): spindle bodies from a centreline and a
  width profile, fins, tapered arms and jointed legs, eyes and spots, coloured by smooth HSV
  gradients along and across the body (`many_hued`: a wrasse/parrotfish-like fish whose hues run
  from blue and green through yellow and orange to magenta, the water's hue among them). Each
  has a height field (a dome over every body part) used for shading only: the body is curved in
  its light, flat in its geometry (the photo-model is flat too).
* The estimator's photo is a studio shot of the creature (`studio_photo`: soft frontal light,
  a plain backdrop); in the scene the same creature is lit by the sun (Lambert + a sky fill +
  Blinn-Phong highlights on the wet body) under a colour cast.
* Water: a spectral height field (power law with a wind direction, synthesised by FFT, two
  scales), Schlick-Fresnel mix of a turbid body colour (teal, green, blue or olive) with a sky
  gradient and clouds, sun glitter.
* Occluders: foam patches and foam bands with ragged, bubbly edges (`foam_split`: a band across
  the creature's middle that cuts its visible region in two), floating debris (leaves, twigs).
* Light and sensor: brightness 0.75-1.15, a colour cast per scene plus a small white-balance
  difference per camera, vignetting, blur 0.4-1.2 px, sensor noise 2-6 DN.

Frames: world mm, z up, water plane z = 0; cameras OpenCV; the model frame of DESIGN.md (a photo
pixel (u, v) at ((u - ox)/alpha, (v - oy)/alpha, 0) mm, z into the photo, so a creature lying
face-up has its model z pointing down into the water).

API: `random_scene(seed, params, photo_params, kind, other_photo, empty, distractor, foam_split,
many_hued, ...)` -> `SyntheticScene` (the same object and truth shape as
`sim/renderer.random_scene`); `draw_creature`, `studio_photo`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.geometry import make_pose
from photoservo.vision.photo_model import PhotoModel, PhotoModelParams, build_photo_model
from photoservo.vision.rig import Camera, Rig, project_points
from photoservo.sim.renderer import (
    SynthParams,
    SyntheticScene,
    match_individuals,
    perturb_rig,
    pixel_rays,
    scene_truth,
    synthetic_rig,
)

KINDS = ("squid", "crab", "fish")
PHOTO_SIZE = (384, 256)  # width, height of a creature's photo (px)
_SS = 3  # supersampling of the drawing


# ----------------------------------------------------------------------------- creatures


@dataclass(frozen=True)
class Creature:
    """A creature in its photo frame (PHOTO_SIZE px): albedo (H, W, 3) float32 BGR 0..255,
    cover (H, W) float32 0..1 (anti-aliased outline), height (H, W) float32 0..1 (the body's
    dome, for shading), gloss (H, W) float32 0..1 (specular strength)."""

    kind: str
    albedo: np.ndarray
    cover: np.ndarray
    height: np.ndarray
    gloss: np.ndarray


def _arc(p0: np.ndarray, heading: float, length: float, curl: float, n: int = 16) -> np.ndarray:
    """Points (n, 2) px along an arc from p0 leaving at `heading` (rad) whose direction turns by
    `curl` (rad) over its `length` (px)."""
    s = np.linspace(0.0, 1.0, n)
    ang = heading + curl * s
    steps = np.column_stack([np.cos(ang), np.sin(ang)]) * (length / (n - 1))
    return p0 + np.vstack([[0.0, 0.0], np.cumsum(steps[:-1], axis=0)])


def _ribbon(line: np.ndarray, w0: float, w1: float) -> np.ndarray:
    """Polygon of a ribbon along a polyline whose full width goes from w0 to w1 (px)."""
    t = np.gradient(line, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True) + 1e-9
    nrm = np.column_stack([-t[:, 1], t[:, 0]])
    half = np.linspace(w0, w1, len(line))[:, None] / 2
    return np.vstack([line + nrm * half, (line - nrm * half)[::-1]])


def _fill(canvas: np.ndarray, poly: np.ndarray, part: int) -> None:
    cv2.fillPoly(canvas, [np.rint(poly * 8).astype(np.int32)], part, cv2.LINE_8, 3)


def _spindle(x0: float, x1: float, cy: float, half_w: float, bend: float, blunt: float, n: int = 80) -> np.ndarray:
    """A body outline from x0 (head) to x1 (tail), px: half-width half_w · sin(pi s^blunt)^0.8 about
    a centreline bowed by `bend` px."""
    s = np.linspace(0.0, 1.0, n)
    x = x0 + (x1 - x0) * s
    yc = cy + bend * np.sin(np.pi * s)
    w = half_w * np.sin(np.pi * np.clip(s, 0, 1) ** blunt) ** 0.8
    return np.vstack([np.column_stack([x, yc - w]), np.column_stack([x, yc + w])[::-1]])


def _hsv_bgr(h_deg: np.ndarray, s: np.ndarray, v: np.ndarray) -> np.ndarray:
    """BGR float32 0..255 from hue (deg), saturation and value (0..1) fields."""
    hsv = np.dstack([np.mod(h_deg, 360.0), np.clip(s, 0, 1), np.clip(v, 0, 1)]).astype(np.float32)
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR) * np.float32(255)


def _smooth_field(rng: np.random.Generator, shape: tuple[int, int], cell: float) -> np.ndarray:
    """A smooth random field (float32, zero mean, unit std) with features of about `cell` px."""
    H, W = shape
    g = rng.standard_normal((max(2, int(H / cell) + 3), max(2, int(W / cell) + 3))).astype(np.float32)
    f = cv2.resize(g, (W, H), interpolation=cv2.INTER_CUBIC)
    return (f - f.mean()) / (f.std() + 1e-6)


def draw_creature(kind: str, seed: int, other: bool = False, many_hued: bool = False) -> Creature:
    """A procedural creature (`kind` squid, crab or fish; head/claws to the left), deterministic
    from `seed`. other=True: another individual of the species (other proportions, hue,
    pattern and scale in the photo). many_hued (fish only): smooth gradients from blue and green
    (the water's hues) through yellow and orange to magenta, with wavy blue-green stripes."""
    if kind not in KINDS:
        raise InputError(f"kind '{kind}': choose from {', '.join(KINDS)}")
    rng = np.random.default_rng([seed, 91, int(other), int(many_hued)])
    W, H = PHOTO_SIZE[0] * _SS, PHOTO_SIZE[1] * _SS
    jit = 0.14 if other else 0.06

    def j(k: float = 1.0) -> float:
        return float(1.0 + rng.uniform(-1, 1) * jit * k)

    scale = float(rng.uniform(0.74, 0.9)) if other else float(rng.uniform(0.92, 1.0))
    parts = np.zeros((H, W), np.uint8)  # 1 body, 2 fin/arm/leg, 3 eye, 4 claw
    cx, cy = 0.5 * W, 0.5 * H
    L = 0.8 * W * scale
    if kind == "fish":
        x0, x1 = cx - 0.5 * L, cx + 0.32 * L
        hw = 0.16 * L * j()
        body = _spindle(x0, x1, cy, hw, 0.02 * L * rng.uniform(-1, 1), 0.55 * j(0.5))
        tail_x = cx + 0.5 * L
        fork = 0.17 * L * j()
        _fill(parts, np.array([[x1 - 0.06 * L, cy - 0.04 * L], [tail_x, cy - fork], [tail_x - 0.07 * L, cy],
                               [tail_x, cy + fork], [x1 - 0.06 * L, cy + 0.04 * L]]), 2)
        dors = _arc(np.array([x0 + 0.3 * L, cy - 0.85 * hw]), -0.35, 0.36 * L * j(), 0.6)
        _fill(parts, np.vstack([dors, [[x0 + 0.66 * L, cy - 0.6 * hw]], [[x0 + 0.3 * L, cy - 0.6 * hw]]]), 2)
        anal = _arc(np.array([x0 + 0.55 * L, cy + 0.75 * hw]), 0.4, 0.16 * L * j(), -0.4)
        _fill(parts, np.vstack([anal, [[x0 + 0.72 * L, cy + 0.5 * hw]]]), 2)
        _fill(parts, body, 1)
        eye = (x0 + 0.09 * L, cy - 0.15 * hw)
        cv2.circle(parts, (int(eye[0]), int(eye[1])), int(0.028 * L), 3, -1)
    elif kind == "squid":
        x0, x1 = cx - 0.08 * L, cx + 0.5 * L
        hw = 0.12 * L * j()
        s = np.linspace(0, 1, 60)
        top = np.column_stack([x0 + (x1 - x0) * s, cy - hw * np.sqrt(1 - s) * (1 + 0.15 * np.sin(np.pi * s))])
        mantle = np.vstack([top, np.column_stack([top[:, 0], 2 * cy - top[:, 1]])[::-1]])
        fl, fw = 0.26 * L * j(), 0.15 * L * j()
        _fill(parts, np.array([[x1, cy], [x1 - 0.5 * fl, cy - fw], [x1 - fl, cy], [x1 - 0.5 * fl, cy + fw]]), 2)
        _fill(parts, mantle, 1)
        head_x = x0 - 0.06 * L
        cv2.ellipse(parts, (int(head_x), int(cy)), (int(0.08 * L), int(0.8 * hw)), 0, 0, 360, 1, -1)
        for i in range(8):
            a = math.pi + (i - 3.5) * 0.11 * j() + rng.normal(0, 0.04)
            p0 = np.array([head_x - 0.05 * L, cy + (i - 3.5) * 0.09 * hw])
            _fill(parts, _ribbon(_arc(p0, a, 0.2 * L * j(1.5), rng.normal(0, 0.6)), 0.03 * L, 0.005 * L), 2)
        for sgn in (-1, 1):
            p0 = np.array([head_x - 0.05 * L, cy + sgn * 0.25 * hw])
            arm = _arc(p0, math.pi + sgn * 0.1, 0.36 * L * j(1.5), sgn * rng.uniform(0.1, 0.6))
            _fill(parts, _ribbon(arm, 0.018 * L, 0.01 * L), 2)
            cv2.ellipse(parts, tuple(int(v) for v in arm[-1]), (int(0.028 * L), int(0.011 * L)), 0, 0, 360, 2, -1)
            cv2.circle(parts, (int(head_x), int(cy + sgn * 0.5 * hw)), int(0.02 * L), 3, -1)
    else:  # crab
        ccx = cx + 0.05 * L
        R = 0.15 * L
        rx, ry = R * 0.8 * j(), R * 1.1 * j()
        for sgn in (-1, 1):
            for k in range(4):
                a0 = sgn * (math.pi / 2 - 0.2 + 0.34 * k) * j(0.3)
                p0 = np.array([ccx + 0.35 * rx * math.cos(a0), cy + 0.85 * ry * math.sin(a0)])
                seg1 = _arc(p0, a0, 0.7 * R * j(), 0.0, 6)
                seg2 = _arc(seg1[-1], a0 + sgn * 0.85 * j(), 0.6 * R * j(), 0.0, 6)
                _fill(parts, _ribbon(seg1, 0.14 * R, 0.1 * R), 2)
                _fill(parts, _ribbon(seg2, 0.1 * R, 0.025 * R), 2)
            p0 = np.array([ccx - 0.7 * rx, cy + sgn * 0.5 * ry])
            arm = _arc(p0, math.pi + sgn * 0.55, 0.5 * R * j(), -sgn * 0.7, 8)
            _fill(parts, _ribbon(arm, 0.2 * R, 0.17 * R), 4)
            pc = arm[-1]
            cl = 0.3 * R * j()
            cv2.ellipse(parts, (int(pc[0]), int(pc[1])), (int(cl), int(0.55 * cl)),
                        math.degrees(math.pi + sgn * 0.3), 0, 360, 4, -1)
            for f in (-1, 1):
                finger = _arc(pc + np.array([-cl, sgn * 0.1 * cl]), math.pi + f * 0.3, 0.6 * cl, -f * 0.8, 8)
                _fill(parts, _ribbon(finger, 0.3 * cl, 0.04 * cl), 4)
        th = np.linspace(0, 2 * math.pi, 120)
        bump = 1 + 0.04 * np.sin(7 * th + rng.uniform(0, 6)) + 0.03 * np.sin(3 * th + rng.uniform(0, 6))
        _fill(parts, np.column_stack([ccx + rx * bump * np.cos(th), cy + ry * bump * np.sin(th)]), 1)
        for sgn in (-1, 1):
            cv2.circle(parts, (int(ccx - 0.85 * rx), int(cy + sgn * 0.25 * ry)), int(0.06 * R), 3, -1)

    # colour fields: body coordinate s along x (0 head .. 1 tail) and across (-1 back .. 1 belly)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    ys, xs = np.nonzero(parts)
    s = np.clip((xx - xs.min()) / max(1, xs.max() - xs.min()), 0, 1)
    a = np.clip((yy - cy) / max(1, 0.5 * (ys.max() - ys.min())), -1, 1)
    blotch = _smooth_field(rng, (H, W), 40.0 * _SS)
    hue_shift = float(rng.uniform(-10, 10)) + (float(rng.choice([-1, 1]) * rng.uniform(6, 12)) if other else 0.0)
    if kind == "fish" and many_hued:
        hue = 215 - 265 * s + 25 * a + 8 * blotch  # blue -> green -> yellow -> orange -> magenta
        sat = 0.75 + 0.1 * blotch
        val = 0.82 - 0.12 * np.clip(-a, 0, 1)
        stripes = np.abs(np.sin((yy / (0.05 * L) + 0.6 * np.sin(xx / (0.08 * L))) * math.pi)) < 0.22
        stripes &= a < 0.3
        hue = np.where(stripes, 175 + 10 * s, hue)
        sat = np.where(stripes, 0.85, sat)
    elif kind == "fish":  # a red/orange reef fish, pale belly, dark spots
        hue = 8 + 14 * s + 10 * np.clip(a, 0, 1) + 4 * blotch + hue_shift
        sat = 0.78 - 0.38 * np.clip(a, 0, 1) + 0.06 * blotch
        val = 0.78 + 0.14 * np.clip(a, 0, 1) - 0.08 * np.clip(-a, 0, 1)
    elif kind == "squid":  # translucent pink-orange with chromatophores
        hue = 12 + 10 * s + 5 * blotch + hue_shift
        sat = 0.62 + 0.1 * blotch - 0.1 * (parts == 2)
        val = 0.8 + 0.08 * blotch
    else:  # crab: orange-red carapace, paler legs
        hue = 14 + 5 * blotch + 8 * (parts == 2) + hue_shift
        sat = 0.8 - 0.12 * (parts == 2) + 0.05 * blotch
        val = 0.72 + 0.1 * blotch + 0.08 * (parts == 2)
    albedo = _hsv_bgr(hue, sat, val)
    # spots: darker, redder dots on the body
    n_spots = int(rng.integers(12, 30))
    spots = np.zeros((H, W), np.uint8)
    for _ in range(n_spots):
        k = int(rng.integers(len(xs)))
        cv2.circle(spots, (int(xs[k]), int(ys[k])), int(rng.uniform(0.006, 0.014) * L), 1, -1)
    spots &= (parts == 1).astype(np.uint8)
    albedo[spots > 0] *= np.float32(0.62)
    albedo[parts == 3] = (25.0, 22.0, 30.0)
    # height: a dome over every part (distance to the part's outline), fins and legs flat
    height = np.zeros((H, W), np.float32)
    for part, gain in ((1, 1.0), (4, 0.7), (2, 0.25)):
        m = (parts == part).astype(np.uint8)
        if not m.any():
            continue
        dt = cv2.distanceTransform(m, cv2.DIST_L2, 5)
        r = max(1.0, float(dt.max()))
        height = np.maximum(height, gain * np.sqrt(1 - (1 - np.minimum(dt / r, 1)) ** 2))
    height = cv2.GaussianBlur(height, (0, 0), 1.5 * _SS)
    gloss = np.select([parts == 1, parts == 4, parts == 3, parts == 2], [0.9, 0.8, 1.0, 0.5], 0.0).astype(np.float32)
    cover = (parts > 0).astype(np.float32)

    def down(img: np.ndarray) -> np.ndarray:
        return cv2.resize(img, PHOTO_SIZE, interpolation=cv2.INTER_AREA)

    cov = down(cover)
    inv = np.where(cov > 1e-3, 1 / np.maximum(cov, 1e-3), 0).astype(np.float32)
    return Creature(kind=kind, albedo=down(albedo * cover[..., None]) * inv[..., None], cover=cov,
                    height=down(height), gloss=down(gloss * cover) * inv)


def recoloured(c: Creature, hue_shift_deg: float) -> Creature:
    """The same creature with every hue turned by `hue_shift_deg` (a look-alike of another colour)."""
    hsv = cv2.cvtColor(c.albedo / np.float32(255), cv2.COLOR_BGR2HSV)
    hsv[..., 0] = np.mod(hsv[..., 0] + hue_shift_deg, 360)
    return Creature(c.kind, cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR) * np.float32(255), c.cover, c.height, c.gloss)


def float_buoy(hue_deg: float, rng: np.random.Generator) -> Creature:
    """A look-alike: a fishing float (capsule) in a given hue with a white band."""
    W, H = PHOTO_SIZE
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    rx, ry = 0.3 * W, 0.16 * H * rng.uniform(0.9, 1.3)
    e = ((xx - W / 2) / rx) ** 2 + ((yy - H / 2) / ry) ** 2
    cover = np.clip((1 - e) * 40, 0, 1).astype(np.float32)
    height = np.sqrt(np.clip(1 - e, 0, 1)).astype(np.float32)
    band = np.abs(xx - W / 2 - rng.uniform(-0.3, 0.3) * rx) < 0.1 * rx
    albedo = _hsv_bgr(np.full((H, W), hue_deg), np.where(band, 0.05, 0.85), np.where(band, 0.95, 0.8))
    return Creature("float", albedo, cover, height, np.full((H, W), 0.9, np.float32))


def _normals(c: Creature, relief: float) -> tuple[np.ndarray, np.ndarray]:
    """Height-field slopes (dh/du, dh/dv) of a creature in photo px times `relief` (px of height
    per unit of `height`)."""
    hx = cv2.Sobel(c.height, cv2.CV_32F, 1, 0, ksize=3) / 8 * relief
    hy = cv2.Sobel(c.height, cv2.CV_32F, 0, 1, ksize=3) / 8 * relief
    return hx, hy


def studio_photo(c: Creature, seed: int, backdrop_bgr: tuple[float, float, float] = (232, 234, 236)) -> np.ndarray:
    """The estimator's photo of a creature: soft light from the camera's side, faint highlights,
    on a plain backdrop, with a little noise (BGR uint8, PHOTO_SIZE)."""
    rng = np.random.default_rng([seed, 5])
    hx, hy = _normals(c, 0.08 * PHOTO_SIZE[1])
    n = np.dstack([-hx, -hy, -np.ones_like(hx)])
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    L = np.array([-0.3, -0.4, -1.0], np.float32)
    L /= np.linalg.norm(L)
    lam = np.clip(n @ L, 0, 1)
    col = c.albedo * (0.55 + 0.5 * lam)[..., None] + (60 * c.gloss * lam ** 40)[..., None]
    img = np.asarray(backdrop_bgr, np.float32) * (1 - c.cover[..., None]) + col * c.cover[..., None]
    img = img + rng.normal(0, 1.5, img.shape).astype(np.float32)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


# ----------------------------------------------------------------------------- the scene


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
    hx, hy = _normals(c, p.relief)
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


# ----------------------------------------------------------------------------- scene generator


def _lying(position: np.ndarray, heading: float) -> np.ndarray:
    """T_world_model of a creature lying face-up at `position` (world mm), model x at `heading`."""
    c, s = math.cos(heading), math.sin(heading)
    return make_pose(np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]]), np.asarray(position, float))


def _place_rig(rng: np.random.Generator, rig: Rig, corners_world: np.ndarray, target: np.ndarray,
               distance: float, tilt: float) -> np.ndarray | None:
    """T_world_left with `target` (world) at depth `distance` in the left camera, the optical axis
    `tilt` (rad) from straight down, and every corner inside both images (12 px margin)."""
    for _ in range(300):
        az, roll = rng.uniform(-math.pi, math.pi, 2)
        z = np.array([math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az), -math.cos(tilt)])
        x0 = np.cross(z, [0.0, 0.0, 1.0])
        x0 = x0 / np.linalg.norm(x0) if np.linalg.norm(x0) > 1e-6 else np.array([1.0, 0.0, 0.0])
        y0 = np.cross(z, x0)
        x = math.cos(roll) * x0 + math.sin(roll) * y0
        R = np.column_stack([x, np.cross(z, x), z])
        px = rng.uniform([60, 60], [rig.left.width - 61, rig.left.height - 61])
        ray = cv2.undistortPoints(px.reshape(1, 1, 2), rig.left.K, rig.left.dist).reshape(2)
        C = target - R @ (np.array([ray[0], ray[1], 1.0]) * distance)
        if C[2] < 80:
            continue
        T = make_pose(R, C)
        Xl = (corners_world - C) @ R
        Xr = Xl @ rig.R.T + rig.T
        ok = True
        for cam, X in ((rig.left, Xl), (rig.right, Xr)):
            uv = project_points(X, cam)
            ok &= bool(np.all(np.isfinite(uv)) and np.all(uv >= 12) and np.all(uv[:, 0] <= cam.width - 13)
                       and np.all(uv[:, 1] <= cam.height - 13))
        if ok:
            return T
    return None


_WATERS = (  # body colour BGR: teal, green, blue, olive
    (95.0, 92.0, 40.0), (70.0, 95.0, 45.0), (110.0, 70.0, 30.0), (55.0, 88.0, 80.0))


def _split_check(model: PhotoModel, alpha: float, band: FoamBand, T_world_model: np.ndarray) -> bool:
    """Does the band's core cut the creature's photo mask into two pieces, each >= 15 % of it?"""
    ys, xs = np.nonzero(model.mask)
    Xm = np.column_stack([(xs - model.origin_px[0]) / alpha, (ys - model.origin_px[1]) / alpha, np.zeros(len(xs))])
    Pw = Xm @ T_world_model[:3, :3].T + T_world_model[:3, 3]
    c, s = math.cos(band.direction), math.sin(band.direction)
    across = -(Pw[:, 0] - band.centre[0]) * s + (Pw[:, 1] - band.centre[1]) * c
    keep = np.zeros(model.mask.shape, np.uint8)
    keep[ys, xs] = (np.abs(across) > band.half_width * 1.1).astype(np.uint8)
    n, _, stats, _ = cv2.connectedComponentsWithStats(keep, connectivity=8)
    big = np.sort(stats[1:, cv2.CC_STAT_AREA])[::-1] if n > 1 else np.array([])
    return bool(len(big) >= 2 and big[1] >= 0.15 * len(xs))


def random_scene(seed: int, params: SynthParams, photo_params: PhotoModelParams, kind: str = "squid",
                 other_photo: bool = False, empty: bool = False, distractor: bool = False,
                 foam_split: bool = False, many_hued: bool = False, distance_mm: float | None = None,
                 tilt_deg: float | None = None, rig: Rig | None = None) -> SyntheticScene:
    """A seeded harbour scene: a procedural creature (`kind`; a new individual per seed) lying
    face-up on the water, seen by `rig` (default `synthetic_rig()`) rendered with the configured
    calibration error (`params.calib_*`; `SyntheticScene.rig` is the rig the estimator is told).
    Geometry from `params`: depth `distance_mm` (default random in params.distance_mm), tilt of
    the optical axis from the creature's normal `tilt_deg` (default up to params.tilt_max_deg),
    length in params.length_mm (shortened to params.max_image_fraction of the image height).
    Everything else (water, light, occluders) is this generator's own (module docstring).

    other_photo: the estimator's photo shows another individual (truth matched by mask area and
    centroid, `match_individuals`, as in `sim/renderer.random_scene`). empty: no creature.
    distractor: a look-alike (another species, a recoloured copy, or a float in the creature's
    hue) elsewhere in view. foam_split: a foam band across the creature's middle that cuts its
    visible region in two. many_hued (fish): the many-hued creature (see `draw_creature`).
    Without foam_split, a third of the scenes get a foam patch over ~12 % of the creature.

    Truth: the estimate JSON of DESIGN.md for the estimator's photo-model (built from
    `SyntheticScene.photo` with `photo_params`) in the true left camera frame, plus distance_mm,
    tilt_deg, same_photo, creature_size_mm, calibration_error, effects, distractors, seed,
    generator, kind, many_hued, foam_split (the band really cuts the creature in two), foam_cover
    (share of the creature under foam, left image) and light."""
    if kind not in KINDS:
        raise InputError(f"kind '{kind}': choose from {', '.join(KINDS)}")
    if many_hued and kind != "fish":
        raise InputError("many_hued: only for kind 'fish'")
    rng = np.random.default_rng([int(seed), 4243])
    rig = synthetic_rig() if rig is None else rig
    rig_true, calib = perturb_rig(rig, rng, params.calib_rotation_deg, params.calib_focal_pct)
    creature = draw_creature(kind, seed, many_hued=many_hued)
    backdrops = [(232, 234, 236), (214, 224, 230), (200, 204, 205), (226, 232, 224)]
    render_photo = studio_photo(creature, seed, backdrops[int(rng.integers(4))])
    model_A = build_photo_model(render_photo, photo_params)
    if other_photo:
        photo = studio_photo(draw_creature(kind, seed + 7919, other=True, many_hued=many_hued), seed + 1,
                             backdrops[int(rng.integers(4))])
        model_B = build_photo_model(photo, photo_params)
    else:
        photo, model_B = render_photo, model_A
    dist = float(rng.uniform(*params.distance_mm)) if distance_mm is None else float(distance_mm)
    tilt = math.radians(float(rng.uniform(0, params.tilt_max_deg)) if tilt_deg is None else float(tilt_deg))
    heading = float(rng.uniform(-math.pi, math.pi))
    wA, hA = model_A.size_px
    length = float(rng.uniform(*params.length_mm))
    length = min(length, params.max_image_fraction * rig.left.height * dist / rig.left.K[1, 1] / math.hypot(1, hA / wA))
    T_wm = _lying(np.zeros(3), heading)
    T_wl = None
    for _ in range(8):
        alpha_A = wA / length
        corners = np.array([[sx * wA / 2, sy * hA / 2, 0.0] for sx in (-1, 1) for sy in (-1, 1)]) / alpha_A
        T_wl = _place_rig(rng, rig_true, corners @ T_wm[:3, :3].T, np.zeros(3), dist, tilt)
        if T_wl is not None:
            break
        length *= 0.8
    if T_wl is None:
        raise InputError(f"harbour scene: cannot fit the creature in both images at {dist:.0f} mm")
    relief = 0.12 * hA  # photo px of body height: a creature about a fifth as thick as it is wide
    target = Placed(creature, T_wm, alpha_A, model_A.origin_px, relief)
    # light
    el, az = math.radians(rng.uniform(30, 70)), rng.uniform(-math.pi, math.pi)
    sun = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    cast = 1 + rng.uniform(-0.08, 0.08, 3)
    light = Light(sun_dir=sun, gain=float(rng.uniform(0.75, 1.15)), cast=cast / cast.mean(),
                  white_balance=(1 + rng.uniform(-0.02, 0.02, 3), 1 + rng.uniform(-0.02, 0.02, 3)),
                  noise=float(rng.uniform(2, 6)), blur=float(rng.uniform(0.4, 1.2)))
    water = HarbourWater(body_bgr=np.array(_WATERS[int(rng.integers(4))]) * rng.uniform(0.85, 1.15),
                         zenith_bgr=np.array([190.0, 140.0, 90.0]), horizon_bgr=np.array([225.0, 220.0, 210.0]),
                         slope=float(rng.uniform(0.03, 0.09)), wind=float(rng.uniform(-math.pi, math.pi)),
                         glitter=float(rng.uniform(0.3, 1.5)), seed=int(rng.integers(1 << 30)))
    # occluders: foam elsewhere, maybe a patch over the creature, or a band across it
    R_wm = T_wm[:3, :3]
    bands: list[FoamBand] = []
    patches = [[*rng.normal(0, 1.5 * length, 2), rng.uniform(0.08, 0.25) * length] for _ in range(int(rng.integers(2, 5)))]
    split = False
    if foam_split:
        along = float(rng.uniform(-0.12, 0.12)) * length
        centre = R_wm @ np.array([along, 0.0, 0.0])
        ax = R_wm @ np.array([1.0, 0.0, 0.0])
        direction = math.atan2(ax[1], ax[0]) + math.pi / 2 + rng.uniform(-0.35, 0.35)
        bands.append(FoamBand((float(centre[0]), float(centre[1])), direction,
                              float(rng.uniform(0.05, 0.08)) * length, 4.0 * length))
        split = _split_check(model_A, alpha_A, bands[0], T_wm)
    elif rng.random() < 1 / 3:
        ys, xs = np.nonzero(model_A.mask)
        k = int(rng.integers(len(xs)))
        pm = np.array([(xs[k] - model_A.origin_px[0]) / alpha_A, (ys[k] - model_A.origin_px[1]) / alpha_A, 0.0])
        pw = R_wm @ pm
        area = len(xs) / alpha_A ** 2
        patches.append([pw[0], pw[1], math.sqrt(0.12 * area / math.pi) * 1.1])
    debris = []
    for _ in range(int(rng.integers(0, 6))):
        q = rng.normal(0, 1.2 * length, 2)
        leaf = rng.random() < 0.6
        debris.append([q[0], q[1], rng.uniform(10, 40) if leaf else rng.uniform(30, 90),
                       rng.uniform(5, 15) if leaf else rng.uniform(2, 4), rng.uniform(0, math.pi), 0 if leaf else 1])
    # look-alike, in view, away from the creature
    distractors: list[Placed] = []
    dinfo: list[dict] = []
    T_lw = np.linalg.inv(T_wl)
    if distractor:
        choice = ("species", "recolour", "float")[int(rng.integers(3))]
        if choice == "species":
            other_kind = [k for k in KINDS if k != kind][int(rng.integers(2))]
            dc = draw_creature(other_kind, seed + 31)
        elif choice == "recolour":
            dc = recoloured(creature, float(rng.choice([-1, 1]) * rng.uniform(90, 150)))
        else:
            inner = model_A.inner_hue.astype(float) * 2
            dc = float_buoy(float(np.degrees(np.angle(np.mean(np.exp(1j * np.radians(inner)))))), rng)
        d_alpha = PHOTO_SIZE[0] * 0.8 / (length * (0.5 if choice == "float" else rng.uniform(0.8, 1.2)))
        cam = rig_true.left
        for _ in range(200):
            px = rng.uniform([50, 50], [cam.width - 51, cam.height - 51])
            ray = cv2.undistortPoints(px.reshape(1, 1, 2), cam.K, cam.dist).reshape(2)
            dw = T_wl[:3, :3] @ np.array([ray[0], ray[1], 1.0])
            if dw[2] >= -1e-6:
                continue
            Pw = T_wl[:3, 3] + (-T_wl[2, 3] / dw[2]) * dw
            if np.hypot(*Pw[:2]) > 1.25 * length:
                T_d = _lying(Pw, float(rng.uniform(-math.pi, math.pi)))
                distractors.append(Placed(dc, T_d, d_alpha, (PHOTO_SIZE[0] / 2 - 0.5, PHOTO_SIZE[1] / 2 - 0.5),
                                          0.12 * PHOTO_SIZE[1] * 0.6))
                dinfo.append({"kind": choice, "position_mm": [float(v) for v in (T_lw @ T_d)[:3, 3]]})
                break
    scene = HarbourScene(water=water, target=None if empty else target, distractors=tuple(distractors),
                         patches=np.array(patches, float).reshape(-1, 3), bands=tuple(bands),
                         debris=np.array(debris, float).reshape(-1, 6), light=light, seed=int(seed))
    noise_rng = np.random.default_rng([int(seed), 77])
    T_wr = T_wl @ np.linalg.inv(make_pose(rig_true.R, rig_true.T))
    left, cov_l = render_camera(scene, rig_true.left, T_wl, light.white_balance[0], noise_rng)
    right, cov_r = render_camera(scene, rig_true.right, T_wr, light.white_balance[1], noise_rng)
    # ground truth for the estimator's photo-model
    T_lm = T_lw @ T_wm
    R = T_lm[:3, :3]
    alpha, origin_mm = (alpha_A, np.zeros(3)) if not other_photo else match_individuals(model_A, model_B, alpha_A)
    position = R @ origin_mm + T_lm[:3, 3]
    scene = dataclasses.replace(scene, coverage=(cov_l[0], cov_r[0]))
    foam_cover = 0.0 if empty else float(np.clip(1 - cov_l[0].sum() / max(float(cov_l[1].sum()), 1e-6), 0, 1))
    truth = {
        **scene_truth(empty, R, position, alpha, model_B),
        "distance_mm": float(T_lm[2, 3]),
        "same_photo": not other_photo,
        "creature_size_mm": [float(wA / alpha_A), float(hA / alpha_A)],
        "calibration_error": calib,
        "effects": ["light", "waves", "glitter", "noise", "blur", "vignetting", "foam", "debris"],
        "distractors": dinfo,
        "seed": int(seed),
        "generator": "harbour",
        "kind": kind,
        "many_hued": bool(many_hued),
        "foam_split": bool(split),
        "foam_cover": round(foam_cover, 4),
        "light": {"gain": light.gain, "cast_bgr": [float(v) for v in light.cast], "noise_dn": light.noise,
                  "blur_px": light.blur, "sun_elevation_deg": float(np.degrees(el))},
    }
    return SyntheticScene(left=left, right=right, rig=rig, rig_true=rig_true, truth=truth, photo=photo,
                          render_photo=render_photo, scene=scene, T_world_left=T_wl)

