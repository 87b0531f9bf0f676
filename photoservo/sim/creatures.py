"""Procedural creatures of the second scene generator (`sim/harbour.py`): bodies drawn from
centrelines, width profiles, fins, tapered arms and jointed legs, coloured by smooth HSV
gradients, with a height field (a dome over every body part) for shading, and the studio photo
of one that the estimator is given. Independent of `sim/specimens.py`.

Photo frame: PHOTO_SIZE px, head / claws to the left (-x), drawn at _SS x supersampling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from photoservo.errors import InputError

KINDS = ("squid", "crab", "fish")
PHOTO_SIZE = (384, 256)  # width, height of a creature's photo (px)
_SS = 3  # supersampling of the drawing


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



def _fish(parts: np.ndarray, rng: np.random.Generator, j, cx: float, cy: float, L: float) -> None:
    """A spindle body with a forked tail, dorsal and anal fins and an eye, into `parts`."""
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


def _squid(parts: np.ndarray, rng: np.random.Generator, j, cx: float, cy: float, L: float) -> None:
    """A mantle with tail fins, a head with eyes, eight arms and two tentacles, into `parts`."""
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


def _crab(parts: np.ndarray, rng: np.random.Generator, j, cx: float, cy: float, L: float) -> None:
    """A bumpy carapace, four jointed legs a side, two claws with pincers and eyes, into `parts`."""
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


def _albedo(kind: str, many_hued: bool, other: bool, parts: np.ndarray, rng: np.random.Generator, cy: float,
            L: float) -> np.ndarray:
    """Colour (BGR float32) of every part: HSV fields over the body coordinates s along x (0 head
    .. 1 tail) and a across (-1 back .. 1 belly), a smooth blotch field, dark spots, black eyes."""
    H, W = parts.shape
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
    spots = np.zeros((H, W), np.uint8)
    for _ in range(int(rng.integers(12, 30))):
        k = int(rng.integers(len(xs)))
        cv2.circle(spots, (int(xs[k]), int(ys[k])), int(rng.uniform(0.006, 0.014) * L), 1, -1)
    spots &= (parts == 1).astype(np.uint8)
    albedo[spots > 0] *= np.float32(0.62)
    albedo[parts == 3] = (25.0, 22.0, 30.0)
    return albedo


def _layers(kind: str, parts: np.ndarray, albedo: np.ndarray) -> Creature:
    """The Creature at PHOTO_SIZE from the supersampled part map and albedo: height a dome over
    every part (distance to its outline; fins and legs flatter), gloss per part, premultiplied
    area resampling so that outlines stay clean."""
    height = np.zeros(parts.shape, np.float32)
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
    {"fish": _fish, "squid": _squid, "crab": _crab}[kind](parts, rng, j, cx, cy, L)
    return _layers(kind, parts, _albedo(kind, many_hued, other, parts, rng, cy, L))


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


def height_slopes(c: Creature, relief: float) -> tuple[np.ndarray, np.ndarray]:
    """Height-field slopes (dh/du, dh/dv) of a creature in photo px times `relief` (px of height
    per unit of `height`)."""
    hx = cv2.Sobel(c.height, cv2.CV_32F, 1, 0, ksize=3) / 8 * relief
    hy = cv2.Sobel(c.height, cv2.CV_32F, 0, 1, ksize=3) / 8 * relief
    return hx, hy


def studio_photo(c: Creature, seed: int, backdrop_bgr: tuple[float, float, float] = (232, 234, 236)) -> np.ndarray:
    """The estimator's photo of a creature: soft light from the camera's side, faint highlights,
    on a plain backdrop, with a little noise (BGR uint8, PHOTO_SIZE)."""
    rng = np.random.default_rng([seed, 5])
    hx, hy = height_slopes(c, 0.08 * PHOTO_SIZE[1])
    n = np.dstack([-hx, -hy, -np.ones_like(hx)])
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    L = np.array([-0.3, -0.4, -1.0], np.float32)
    L /= np.linalg.norm(L)
    lam = np.clip(n @ L, 0, 1)
    col = c.albedo * (0.55 + 0.5 * lam)[..., None] + (60 * c.gloss * lam ** 40)[..., None]
    img = np.asarray(backdrop_bgr, np.float32) * (1 - c.cover[..., None]) + col * c.cover[..., None]
    img = img + rng.normal(0, 1.5, img.shape).astype(np.float32)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)

