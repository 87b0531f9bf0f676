"""Target photos the project draws itself: a squid, a crab and a fish, textured, on a plain
backdrop, deterministic from a seed — the "one photo of that kind of creature" of the method.

`specimen(kind, seed, other=False)` draws the reference photo; `other=True` draws "another
individual of the same species, as a photo from the web would show it": different outline
details (proportions, fins, arms, legs), colouring (hue, saturation, pattern) and scale, on a
different backdrop. Both photos show the creature in the same orientation (head/arms to the left,
photographed from above or from the side), so one model-frame rotation fits both.

The shipped PNGs in examples/photos/ are `specimen(kind, 0)` and `specimen(kind, 0, other=True)`;
regenerate them with `python -m photoservo.sim.specimens examples/photos`.
"""

from __future__ import annotations

import functools
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from photoservo.errors import InputError

SPECIES = ("squid", "crab", "fish")
PHOTO_SIZE = (360, 240)  # width, height (px) of the reference photos
_SS = 3  # supersampling factor for drawing (anti-aliased edges)


@dataclass(frozen=True)
class _Look:
    """What differs between two individuals/photos: colour shift, scale, backdrop."""

    hue_shift: float  # OpenCV hue steps added to the creature's colours
    sat_gain: float  # saturation multiplier
    val_gain: float  # brightness multiplier
    scale: float  # creature size in the photo relative to the reference photo
    backdrop_bgr: tuple[int, int, int]
    jitter: float  # spread of the outline parameters (fraction)


def _look(rng: np.random.Generator, other: bool) -> _Look:
    if not other:
        return _Look(0.0, 1.0, 1.0, 1.0, (236, 238, 240), 0.04)
    backdrops = [(214, 222, 228), (200, 205, 206), (228, 232, 226), (190, 196, 204)]
    return _Look(
        hue_shift=float(rng.choice([-1, 1]) * rng.uniform(3, 6)),
        sat_gain=float(rng.uniform(0.8, 1.15)),
        val_gain=float(rng.uniform(0.85, 1.1)),
        scale=float(rng.uniform(0.72, 0.86)),
        backdrop_bgr=backdrops[int(rng.integers(len(backdrops)))],
        jitter=0.12,
    )


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int], cell_px: float) -> np.ndarray:
    """Smooth random field in [-1, 1] with features of about `cell_px` px (float32, H x W)."""
    H, W = shape
    gh, gw = max(2, int(H / cell_px) + 2), max(2, int(W / cell_px) + 2)
    g = rng.standard_normal((gh, gw)).astype(np.float32)
    f = cv2.resize(g, (W, H), interpolation=cv2.INTER_CUBIC)
    return np.clip(f / (3 * f.std() + 1e-6), -1, 1)


def _tapered(canvas: np.ndarray, pts: np.ndarray, w0: float, w1: float, color: tuple) -> None:
    """Draw a polyline whose width tapers from w0 to w1 (px), as a filled polygon."""
    seg = np.diff(pts, axis=0)
    nrm = np.column_stack([-seg[:, 1], seg[:, 0]])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True) + 1e-9
    nrm = np.vstack([nrm, nrm[-1:]])
    w = np.linspace(w0, w1, len(pts))[:, None] / 2
    poly = np.vstack([pts + nrm * w, (pts - nrm * w)[::-1]])
    cv2.fillPoly(canvas, [np.rint(poly * 16).astype(np.int32)], color, cv2.LINE_AA, 4)


def _curve(p0: np.ndarray, direction: float, length: float, bend: float, n: int = 24) -> np.ndarray:
    """Points along a gently curving arc starting at p0 (px), initial heading `direction` (rad)."""
    s = np.linspace(0, 1, n)
    ang = direction + bend * s
    step = length / (n - 1)
    d = np.column_stack([np.cos(ang), np.sin(ang)]) * step
    return p0 + np.vstack([[0, 0], np.cumsum(d[:-1], axis=0)])


def _j(rng: np.random.Generator, look: _Look, k: float = 1.0) -> float:
    """A jitter factor around 1 for one outline parameter."""
    return float(1 + rng.uniform(-1, 1) * look.jitter * k)


def _squid(rng: np.random.Generator, look: _Look, S: int) -> tuple[np.ndarray, np.ndarray]:
    """Dorsal view of a squid, mantle to the right, arms to the left. Returns (paint id map, base)."""
    W, H = PHOTO_SIZE[0] * S, PHOTO_SIZE[1] * S
    m = np.zeros((H, W), np.uint8)  # 1 body, 2 fin, 3 arm, 4 eye
    cx, cy, L = 0.5 * W, 0.5 * H, 0.62 * W * look.scale
    mw = 0.17 * L * _j(rng, look)  # mantle half-width
    x0, x1 = cx - 0.12 * L, cx + 0.5 * L * _j(rng, look, 0.5)  # mantle from head to tail tip
    t = np.linspace(0, 1, 60)
    top = np.column_stack([x0 + (x1 - x0) * t, cy - mw * np.sqrt(np.clip(1 - t, 0, 1)) * (1 - 0.25 * t) * (0.9 + 0.1 * np.sin(np.pi * t))])
    bot = np.column_stack([top[:, 0], 2 * cy - top[:, 1]])[::-1]
    mantle = np.vstack([top, bot])
    # fins: a rhombus at the tail
    fl = 0.3 * L * _j(rng, look)
    fw = 0.2 * L * _j(rng, look)
    fx = x1 - 0.05 * L
    fin = np.array([[fx, cy], [fx - fl * 0.55, cy - fw], [fx - fl, cy], [fx - fl * 0.55, cy + fw]])
    cv2.fillPoly(m, [np.rint(fin * 16).astype(np.int32)], 2, cv2.LINE_AA, 4)
    cv2.fillPoly(m, [np.rint(mantle * 16).astype(np.int32)], 1, cv2.LINE_AA, 4)
    # head
    hx = x0 - 0.04 * L
    cv2.ellipse(m, (int(hx), int(cy)), (int(0.09 * L), int(0.75 * mw)), 0, 0, 360, 1, -1, cv2.LINE_AA)
    # eight arms and two long tentacles, fanning to the left
    n_arms = 8
    for i in range(n_arms):
        a = np.pi + (i - (n_arms - 1) / 2) * 0.14 * _j(rng, look) + rng.normal(0, 0.03)
        p0 = np.array([hx - 0.05 * L, cy + (i - 3.5) * 0.08 * mw])
        arm = _curve(p0, a, 0.22 * L * _j(rng, look, 1.5), rng.normal(0, 0.5))
        _tapered(m, arm, 0.035 * L, 0.006 * L, 3)
    for sgn in (-1, 1):
        p0 = np.array([hx - 0.05 * L, cy + sgn * 0.2 * mw])
        ten = _curve(p0, np.pi + sgn * 0.12, 0.42 * L * _j(rng, look, 1.5), sgn * rng.uniform(0.1, 0.5))
        _tapered(m, ten, 0.022 * L, 0.012 * L, 3)
        club = ten[-1]
        cv2.ellipse(m, tuple(int(v) for v in club), (int(0.03 * L), int(0.012 * L)), 0, 0, 360, 3, -1, cv2.LINE_AA)
    for sgn in (-1, 1):
        cv2.circle(m, (int(hx), int(cy + sgn * 0.55 * mw)), int(0.022 * L), 4, -1, cv2.LINE_AA)
    base = {1: (95, 120, 205), 2: (110, 135, 210), 3: (100, 128, 200), 4: (40, 40, 60)}
    return m, base


def _crab(rng: np.random.Generator, look: _Look, S: int) -> tuple[np.ndarray, np.ndarray]:
    """Dorsal view of a crab, claws to the left."""
    W, H = PHOTO_SIZE[0] * S, PHOTO_SIZE[1] * S
    m = np.zeros((H, W), np.uint8)  # 1 carapace, 2 claw, 3 leg, 4 eye
    cx, cy = 0.56 * W, 0.5 * H
    R = 0.125 * W * look.scale
    rx, ry = R * 0.85 * _j(rng, look), R * 1.15 * _j(rng, look)  # wide across (rows), short along x
    # legs: four per side, jointed, pointing backwards/outwards
    for sgn in (-1, 1):
        for k in range(4):
            a0 = sgn * (np.pi / 2 - 0.15 + 0.33 * k) * _j(rng, look, 0.3)  # from +x axis, rows down
            p0 = np.array([cx + 0.3 * rx * np.cos(a0), cy + 0.85 * ry * np.sin(a0)])
            seg1 = _curve(p0, a0, 0.75 * R * _j(rng, look), 0.0, 6)
            seg2 = _curve(seg1[-1], a0 + sgn * 0.9 * _j(rng, look), 0.6 * R * _j(rng, look), 0.0, 6)
            _tapered(m, seg1, 0.13 * R, 0.1 * R, 3)
            _tapered(m, seg2, 0.1 * R, 0.03 * R, 3)
    # claws: arm segment then a pincer (two fingers)
    for sgn in (-1, 1):
        p0 = np.array([cx - 0.7 * rx, cy + sgn * 0.55 * ry])
        arm = _curve(p0, np.pi + sgn * 0.6, 0.55 * R * _j(rng, look), -sgn * 0.6, 8)
        _tapered(m, arm, 0.18 * R, 0.16 * R, 2)
        pc = arm[-1]
        cl = 0.28 * R * _j(rng, look)
        cv2.ellipse(m, (int(pc[0]), int(pc[1])), (int(cl), int(0.55 * cl)), float(np.degrees(np.pi + sgn * 0.25)),
                    0, 360, 2, -1, cv2.LINE_AA)
        tip = pc + np.array([-1.0, sgn * 0.1]) * cl
        for f in (-1, 1):
            finger = _curve(tip, np.pi + f * 0.35, 0.55 * cl, -f * 0.7, 8)
            _tapered(m, finger, 0.3 * cl, 0.05 * cl, 2)
    # carapace: an ellipse with a toothed front margin
    ang = np.linspace(0, 2 * np.pi, 240, endpoint=False)
    teeth = 1 + 0.05 * np.maximum(0, np.sin(9 * ang)) * (np.cos(ang) < 0.2)
    rim = np.column_stack([cx + rx * np.cos(ang) * teeth, cy + ry * np.sin(ang) * teeth])
    cv2.fillPoly(m, [np.rint(rim * 16).astype(np.int32)], 1, cv2.LINE_AA, 4)
    for sgn in (-1, 1):
        cv2.circle(m, (int(cx - 0.88 * rx), int(cy + sgn * 0.22 * ry)), int(0.07 * R), 4, -1, cv2.LINE_AA)
    base = {1: (40, 95, 215), 2: (35, 80, 200), 3: (50, 110, 220), 4: (25, 25, 35)}
    return m, base


def _fish(rng: np.random.Generator, look: _Look, S: int) -> tuple[np.ndarray, np.ndarray]:
    """Side view of a perch-like fish, head to the left."""
    W, H = PHOTO_SIZE[0] * S, PHOTO_SIZE[1] * S
    m = np.zeros((H, W), np.uint8)  # 1 body, 2 fin, 3 belly, 4 eye
    L = 0.7 * W * look.scale
    x0, cy = 0.5 * W - 0.5 * L, 0.52 * H
    bl = 0.8 * L  # body length (without tail fin)
    d = 0.26 * L * _j(rng, look)  # body depth
    t = np.linspace(0, 1, 80)
    prof = np.sin(np.pi * np.clip(t, 0, 1) ** 0.75) ** 0.8
    top = np.column_stack([x0 + bl * t, cy - 0.55 * d * prof - 0.02 * d])
    bot = np.column_stack([x0 + bl * t, cy + 0.45 * d * prof + 0.02 * d])
    body = np.vstack([top, bot[::-1]])
    # tail fin (forked)
    tx = x0 + bl * 0.97
    tl = 0.24 * L * _j(rng, look)
    fork = 0.35 * _j(rng, look, 2)
    tail = np.array([[tx - 0.03 * L, cy - 0.05 * d], [tx + tl, cy - 0.55 * d * _j(rng, look)],
                     [tx + tl * (1 - fork), cy], [tx + tl, cy + 0.5 * d * _j(rng, look)], [tx - 0.03 * L, cy + 0.05 * d]])
    cv2.fillPoly(m, [np.rint(tail * 16).astype(np.int32)], 2, cv2.LINE_AA, 4)
    # dorsal fins (spiny front, soft rear), pelvic and anal fins
    dx0 = x0 + 0.3 * bl
    dorsal = [[dx0, cy - 0.5 * d]]
    n_sp = int(rng.integers(7, 11))
    for k in range(n_sp):
        xk = dx0 + (k + 0.5) * 0.32 * bl / n_sp
        dorsal += [[xk, cy - (0.5 + 0.32 * _j(rng, look) * (1 - 0.5 * k / n_sp)) * d], [xk + 0.16 * bl / n_sp, cy - 0.6 * d]]
    dorsal += [[dx0 + 0.55 * bl, cy - 0.55 * d * _j(rng, look, 0.5) - 0.2 * d], [dx0 + 0.6 * bl, cy - 0.2 * d]]
    cv2.fillPoly(m, [np.rint(np.array(dorsal) * 16).astype(np.int32)], 2, cv2.LINE_AA, 4)
    anal = np.array([[x0 + 0.6 * bl, cy + 0.35 * d], [x0 + 0.66 * bl, cy + 0.7 * d * _j(rng, look)],
                     [x0 + 0.8 * bl, cy + 0.3 * d]])
    cv2.fillPoly(m, [np.rint(anal * 16).astype(np.int32)], 2, cv2.LINE_AA, 4)
    cv2.fillPoly(m, [np.rint(body * 16).astype(np.int32)], 1, cv2.LINE_AA, 4)
    belly = np.vstack([np.column_stack([x0 + bl * t, cy + 0.15 * d * prof]), bot[::-1]])
    cv2.fillPoly(m, [np.rint(belly * 16).astype(np.int32)], 3, cv2.LINE_AA, 4)
    pelvic = np.array([[x0 + 0.3 * bl, cy + 0.3 * d], [x0 + 0.36 * bl, cy + 0.68 * d * _j(rng, look)],
                       [x0 + 0.44 * bl, cy + 0.32 * d]])
    cv2.fillPoly(m, [np.rint(pelvic * 16).astype(np.int32)], 2, cv2.LINE_AA, 4)
    cv2.circle(m, (int(x0 + 0.1 * bl), int(cy - 0.1 * d)), int(0.045 * L), 4, -1, cv2.LINE_AA)
    base = {1: (60, 140, 120), 2: (50, 110, 170), 3: (70, 185, 215), 4: (20, 20, 20)}
    return m, base


def _paint(kind: str, rng: np.random.Generator, look: _Look) -> np.ndarray:
    """Colour the part map: base colours, smooth mottling, species pattern, shading."""
    S = _SS
    m, base = {"squid": _squid, "crab": _crab, "fish": _fish}[kind](rng, look, S)
    H, W = m.shape
    img = np.zeros((H, W, 3), np.float32)
    for k, c in base.items():
        img[m == k] = c
    on = m > 0
    mott = _smooth_noise(rng, (H, W), 14 * S)
    fine = _smooth_noise(rng, (H, W), 2.5 * S)
    img *= (1 + 0.18 * mott + 0.08 * fine)[..., None]
    if kind == "squid":  # chromatophores: many small dark red-brown dots, denser on the mantle
        ys, xs = np.nonzero(m == 1)
        for i in rng.choice(len(xs), size=min(len(xs), 420), replace=False):
            r = int(rng.uniform(1.0, 2.6) * S)
            cv2.circle(img, (int(xs[i]), int(ys[i])), r, (40, 50, 140), -1, cv2.LINE_AA)
    elif kind == "crab":  # darker speckle and a lighter centre on the carapace
        ys, xs = np.nonzero(m == 1)
        for i in rng.choice(len(xs), size=min(len(xs), 160), replace=False):
            cv2.circle(img, (int(xs[i]), int(ys[i])), int(rng.uniform(1, 3) * S), (25, 55, 160), -1, cv2.LINE_AA)
    elif kind == "fish":  # vertical dark bars and a scale pattern
        n_bars = int(rng.integers(5, 8))
        xx = np.arange(W)[None, :].repeat(H, 0).astype(np.float32)
        xs = np.nonzero(m == 1)[1]
        x0, x1 = xs.min(), xs.max()
        bars = np.cos(2 * np.pi * (xx - x0) / ((x1 - x0) / n_bars) + rng.uniform(0, 6)) > 0.45
        img[bars & ((m == 1) | (m == 3))] *= np.float32([0.55, 0.6, 0.65])
        yy = np.arange(H)[:, None].astype(np.float32)
        scales = (np.sin(xx / (3.0 * S)) * np.sin(yy / (2.6 * S) + xx / (6.0 * S)) > 0.6)
        img[scales & (m == 1)] *= 0.9
    img[~on] = 0
    img = np.clip(img, 0, 255).astype(np.uint8)
    # colour of this individual: hue shift, saturation and brightness
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV).astype(np.float32)
    hsv[..., 0] = (hsv[..., 0] + look.hue_shift) % 180
    hsv[..., 1] = np.clip(hsv[..., 1] * look.sat_gain, 0, 255)
    hsv[..., 2] = np.clip(hsv[..., 2] * look.val_gain, 0, 255)
    img = cv2.cvtColor(hsv.astype(np.uint8), cv2.COLOR_HSV2BGR).astype(np.float32)
    # backdrop: plain, with a soft vignette, and a faint contact shadow under the creature
    alpha = cv2.GaussianBlur((on * 255).astype(np.uint8), (0, 0), 0.6 * S).astype(np.float32) / 255
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    vig = 1 - 0.08 * (((xx - W / 2) / W) ** 2 + ((yy - H / 2) / H) ** 2) * 4
    bgc = np.float32(look.backdrop_bgr)[None, None] * vig[..., None]
    shadow = cv2.GaussianBlur(np.roll(alpha, (3 * S, 3 * S), (0, 1)), (0, 0), 4 * S)
    bgc = bgc * (1 - 0.18 * shadow[..., None])
    out = img * alpha[..., None] + bgc * (1 - alpha[..., None])
    out = cv2.resize(out, PHOTO_SIZE, interpolation=cv2.INTER_AREA)
    out += rng.normal(0, 1.2, out.shape).astype(np.float32)  # camera noise of the photo
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def specimen(kind: str, seed: int = 0, other: bool = False) -> np.ndarray:
    """A procedural target photo (BGR uint8, PHOTO_SIZE): a `kind` in SPECIES ('squid', 'crab',
    'fish') on a plain backdrop, deterministic from `seed`. `other=True`: another individual of
    the same species photographed differently (outline detail, colouring, scale, backdrop)."""
    if kind not in SPECIES:
        raise InputError(f"specimen '{kind}': unknown, choose one of {', '.join(SPECIES)}")
    return _drawn(kind, int(seed), bool(other)).copy()


@functools.lru_cache(maxsize=12)
def _drawn(kind: str, seed: int, other: bool) -> np.ndarray:
    """The drawing itself, memoised (a pure function of its arguments; ~0.3-1 s to draw), read-only."""
    rng = np.random.default_rng([seed, SPECIES.index(kind), int(other)])
    img = _paint(kind, rng, _look(rng, other))
    img.flags.writeable = False
    return img


def write_examples(folder: str | Path) -> list[Path]:
    """Write <kind>.png and <kind>_other.png for every species (seed 0) into `folder`."""
    from photoservo.fileio import write_image_atomic

    out = []
    for kind in SPECIES:
        for other in (False, True):
            p = Path(folder) / f"{kind}{'_other' if other else ''}.png"
            write_image_atomic(p, specimen(kind, 0, other))
            out.append(p)
    return out


if __name__ == "__main__":
    for p in write_examples(sys.argv[1] if len(sys.argv) > 1 else "examples/photos"):
        print(p)
