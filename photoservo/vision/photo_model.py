"""The photo-model (method step 1-2): from one photo of the kind of creature, the target region
by hue, and sampling points laid at a fixed pixel interval — *inner* points on the target, each
carrying its hue, and *outer* points in a band around it.

Frame: a model point at pixel offset (u, v) from the model origin (the centre of the target's
bounding rectangle in the photo; u along columns, v along rows) sits at (u/alpha, v/alpha, 0) mm
in the model frame, where alpha is the photo's unknown pixel-per-metric ratio (px/mm).

Hue is OpenCV's 8-bit hue, 0..179 (2 degrees per step), circular.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.vision.hs_cells import photo_cells
from photoservo.vision.sampling import brightness, photo_values, plane_values

HUE_BINS = 180
NO_HUE = 255  # marks a pixel too grey or too dark to carry a hue


@dataclass(frozen=True)
class PhotoModelParams:
    """[photo_model] config: how the model is cut out of the photo and sampled."""

    interval_px: float  # sampling interval of inner and outer points in the photo (px)
    band_px: float  # width of the outer band around the target (px)...
    band_frac: float  # ...at most this fraction of the target's longest side
    hue_tolerance: int  # hue distance (0..90) that still counts as "the same hue"
    min_saturation: int  # 0..255: below this a pixel carries no hue
    min_value: int  # 0..255: below this a pixel carries no hue
    max_points: int  # cap on inner + outer points (a coarser grid is used above it)


@dataclass(frozen=True)
class PhotoModel:
    """The 2-D pixel photo-model.

    inner_uv: (N_in, 2) float64 px offsets of inner points from the model origin (S_in).
    inner_hue: (N_in,) uint8 hue of each inner point (0..179).
    outer_uv: (N_out, 2) float64 px offsets of outer points (S_out).
    target_hues: (180,) bool, hues that belong to the target (inner hues widened by the
        tolerance); an outer point scores when the image hue there is *not* one of these.
    size_px: (width, height) of the target's bounding rectangle in the photo (px).
    origin_px: (x, y) of the model origin in the photo (px).
    mask: (H, W) uint8 target mask over the photo (255 = target), for previews.
    inner_value: (N_in,) float32 the photo's grey level at each inner point (the appearance cue,
        `vision/appearance.py`); empty for a model built without a photo (the cue is then off).
    inner_brightness: (N_in,) float32 the photo's brightness max(B, G, R) there (`appearance.body_layout`).
    inner_saturation: (N_in,) float32 the photo's saturation (HSV's S, 0..255) there (`bare_parts.body_purity`).
    colour_cells: (15, 8) bool the photo's colours over hue and saturation (`hs_cells.photo_cells`);
        empty for a model built without a photo (detection's cue on them is then off).
    """

    inner_uv: np.ndarray
    inner_hue: np.ndarray
    outer_uv: np.ndarray
    target_hues: np.ndarray
    size_px: tuple[float, float]
    origin_px: tuple[float, float]
    mask: np.ndarray
    inner_value: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    inner_brightness: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    inner_saturation: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    colour_cells: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), bool))

    @cached_property
    def outer_neighbour(self) -> np.ndarray:
        """(N_out,) int32: each outer point's nearest inner point (the contour rule's pairs,
        `vision/contour.py`); computed once per model."""
        from photoservo.vision.contour import outer_neighbours

        return outer_neighbours(self.inner_uv, self.outer_uv)

    @cached_property
    def contour_points(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The contour rule's kernel inputs, computed once per model: (the inner points that are
        some outer point's neighbour (K, 2) float64, each outer point's neighbour among them
        (N_out,) int32, the outer points (N_out, 2) float64), all C-contiguous."""
        used, neighbour = np.unique(self.outer_neighbour, return_inverse=True)
        inner = np.asarray(self.inner_uv, np.float64).reshape(-1, 2)[used]
        return (np.ascontiguousarray(inner), np.ascontiguousarray(neighbour.reshape(-1), np.int32),
                np.ascontiguousarray(self.outer_uv, np.float64).reshape(-1, 2))

    def size_mm(self, alpha: float) -> tuple[float, float]:
        """Real size (width along model x, height along model y) in mm at ratio alpha (px/mm)."""
        return (self.size_px[0] / alpha, self.size_px[1] / alpha)

    def points_mm(self, alpha: float) -> tuple[np.ndarray, np.ndarray]:
        """Inner and outer points as 3-D model-frame points (mm), z = 0: eq. of method step 2."""
        def lift(uv: np.ndarray) -> np.ndarray:
            return np.column_stack([uv / alpha, np.zeros(len(uv))])
        return lift(self.inner_uv), lift(self.outer_uv)


def hue_image(bgr: np.ndarray, min_saturation: int, min_value: int) -> np.ndarray:
    """OpenCV hue (0..179) of a BGR image; pixels below the saturation or value floor get NO_HUE.
    Each frame of the tracker passes here (twice): cv2 passes only, no numpy temporaries — the
    hue OR-ed with the complement of the in-range mask is NO_HUE (255) wherever S or V is short."""
    return _hsv_hue(cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV), min_saturation, min_value)


def hue_and_saturation(bgr: np.ndarray, min_saturation: int, min_value: int) -> tuple[np.ndarray, np.ndarray]:
    """`hue_image` and the saturation S (uint8 (H, W), HSV's: `sampling.saturation` before its float32) of a
    BGR image, from one HSV conversion."""
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    return _hsv_hue(hsv, min_saturation, min_value), cv2.extractChannel(hsv, 1)


def _hsv_hue(hsv: np.ndarray, min_saturation: int, min_value: int) -> np.ndarray:
    """`hue_image` of an image already converted to HSV (uint8 (H, W, 3))."""
    hued = cv2.inRange(hsv, (0, int(min_saturation), int(min_value)), (255, 255, 255))
    return cv2.bitwise_or(cv2.extractChannel(hsv, 0), cv2.bitwise_not(hued))


def hue_distance(a: np.ndarray | int, b: np.ndarray | int) -> np.ndarray:
    """Circular distance between OpenCV hues (0..90)."""
    d = np.abs(np.asarray(a, dtype=np.int16) - np.asarray(b, dtype=np.int16)) % HUE_BINS
    return np.minimum(d, HUE_BINS - d)


def target_hue_lut(target_hues: np.ndarray) -> np.ndarray:
    """(256,) bool lookup indexed by a hue image's values (`hue_image`, 0..255): True at the
    photo-model's target hues (`PhotoModel.target_hues`, (HUE_BINS,) bool), False at every value
    from HUE_BINS on (NO_HUE among them). The one place this table is built."""
    lut = np.zeros(256, bool)
    lut[:HUE_BINS] = np.asarray(target_hues, bool)[:HUE_BINS]
    return lut


# ----------------------------------------------------------------------------- extraction
# Method step 1: the hue scan from the border inward. The photo's border holds the background;
# its hue (or, for a grey/white backdrop, its brightness) distribution is estimated there, the
# background is grown inward from the border through every pixel that looks like it, and the
# target is what is left: its largest connected component, holes filled.

_BORDER_FRAC = 0.03  # width of the border strip that samples the background (fraction of min(H, W))
_MIN_TARGET_PX = 64  # fewer target pixels than this: no separable target
_MAX_TARGET_FRAC = 0.9  # a "target" covering more of the photo than this was not separated
_BACKDROP_TINT = 6  # Lab a*/b* margin (8-bit units) around the grey backdrop's own tint


def parse_roi(text: str, where: str = "--roi") -> tuple[int, int, int, int]:
    """'X,Y,W,H' (px, top-left corner and size) -> a tuple of ints; anything else is an InputError."""
    parts = [p.strip() for p in str(text).split(",")]
    try:
        vals = tuple(int(p) for p in parts)
    except ValueError:
        raise InputError(f"{where} '{text}': expected X,Y,W,H as four integers (px)") from None
    if len(vals) != 4 or vals[2] <= 0 or vals[3] <= 0 or vals[0] < 0 or vals[1] < 0:
        raise InputError(f"{where} '{text}': expected X,Y,W,H with X, Y >= 0 and W, H > 0 (px)")
    return vals  # type: ignore[return-value]


def _check_photo(photo_bgr: object) -> np.ndarray:
    if not isinstance(photo_bgr, np.ndarray) or photo_bgr.dtype != np.uint8:
        raise InputError("photo: expected an 8-bit colour image")
    if photo_bgr.ndim != 3 or photo_bgr.shape[2] != 3:
        raise InputError(f"photo: expected a colour (H, W, 3) image, got shape {photo_bgr.shape}")
    if min(photo_bgr.shape[:2]) < 16:
        raise InputError(f"photo: image of {photo_bgr.shape[1]}x{photo_bgr.shape[0]} px is too small")
    return photo_bgr


def _background_like(photo_bgr: np.ndarray, params: PhotoModelParams, hsv: np.ndarray | None = None) -> np.ndarray:
    """Pixels whose colour matches the border's distribution (bool, H x W).

    Chromatic border pixels give a set of background hues (bins holding >= 0.5 % of the border,
    widened by the hue tolerance) and a saturation range; achromatic ones (too grey or too dark
    to carry a hue) give a brightness range and a tint range (Lab a*, b*). A pixel is
    background-like when it is chromatic with a background hue and saturation, or achromatic
    with a background brightness and tint. `hsv`: the photo in HSV when the caller has it."""
    hsv = cv2.cvtColor(photo_bgr, cv2.COLOR_BGR2HSV) if hsv is None else hsv
    H, W = hsv.shape[:2]
    b = max(2, round(_BORDER_FRAC * min(H, W)))
    border = np.zeros((H, W), bool)
    border[:b, :] = border[-b:, :] = border[:, :b] = border[:, -b:] = True
    h, s, v = (hsv[..., i].astype(np.int16) for i in range(3))
    achrom = (s < params.min_saturation) | (v < params.min_value)
    bg = np.zeros((H, W), bool)
    n_border = int(border.sum())
    chrom_b = border & ~achrom
    if chrom_b.sum() >= 0.02 * n_border:
        hist = np.bincount(h[chrom_b], minlength=HUE_BINS)[:HUE_BINS]
        present = hist >= 0.005 * n_border
        lut = np.zeros(HUE_BINS, bool)
        for hue in np.flatnonzero(present):
            lut[(hue + np.arange(-params.hue_tolerance, params.hue_tolerance + 1)) % HUE_BINS] = True
        s_lo, s_hi = np.percentile(s[chrom_b], [1, 99])
        v_lo, v_hi = np.percentile(v[chrom_b], [1, 99])
        bg |= (~achrom) & lut[np.minimum(h, HUE_BINS - 1)] & (s >= s_lo - 40) & (s <= s_hi + 40) \
            & (v >= v_lo - 60) & (v <= v_hi + 60)
    achrom_b = border & achrom
    if achrom_b.sum() >= 0.02 * n_border:
        v_lo, v_hi = np.percentile(v[achrom_b], [1, 99])
        # the backdrop's tint too (Lab a*, b*): a faintly coloured pixel too grey to carry a
        # hue — a thin appendage after JPEG chroma subsampling — is not the backdrop
        lab = cv2.cvtColor(photo_bgr, cv2.COLOR_BGR2LAB)
        a_, b_ = lab[..., 1].astype(np.int16), lab[..., 2].astype(np.int16)
        a_lo, a_hi = np.percentile(a_[achrom_b], [1, 99])
        b_lo, b_hi = np.percentile(b_[achrom_b], [1, 99])
        tint = _BACKDROP_TINT
        bg |= achrom & (v >= v_lo - 25) & (v <= v_hi + 25) & (a_ >= a_lo - tint) & (a_ <= a_hi + tint) \
            & (b_ >= b_lo - tint) & (b_ <= b_hi + tint)
    return bg


def _largest_filled(mask: np.ndarray) -> np.ndarray:
    """Largest 8-connected component of a bool mask, its holes filled (uint8 0/255)."""
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if n <= 1:
        return np.zeros(mask.shape, np.uint8)
    k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    comp = labels == k
    # holes: not-target pixels that the outside cannot reach (outside grown from a 1-px frame)
    pad = np.pad(~comp, 1, constant_values=True).astype(np.uint8)
    _, outside = cv2.connectedComponents(pad, connectivity=4)
    reach = outside[1:-1, 1:-1] == outside[0, 0]
    return np.where(comp | ~reach, 255, 0).astype(np.uint8)


def target_mask(photo_bgr: np.ndarray, params: PhotoModelParams,
                roi: tuple[int, int, int, int] | None = None, hsv: np.ndarray | None = None) -> np.ndarray:
    """Method step 1: the target region of the photo (uint8 H x W, 255 = target).

    Without `roi`: the hue scan from the border inward — the background distribution is taken
    from the border strip, grown inward through every background-like pixel connected to the
    border, and the target is the largest remaining component with its holes filled.
    With `roi=(x, y, w, h)` (px): OpenCV GrabCut initialised with that rectangle, for cluttered
    photos whose border is not a plain background. `hsv`: the photo in HSV (uint8 (H, W, 3)) when the
    caller has it (`build_photo_model`), else converted here. Raises InputError when nothing separates."""
    photo_bgr = _check_photo(photo_bgr)
    H, W = photo_bgr.shape[:2]
    if roi is not None:
        x, y, w, h = (int(r) for r in roi)
        if x < 0 or y < 0 or w < 8 or h < 8 or x + w > W or y + h > H:
            raise InputError(f"--roi {x},{y},{w},{h}: must lie inside the {W}x{H} photo and be at least 8x8 px")
        gc = np.zeros((H, W), np.uint8)
        bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
        # a fixed faint dither: flat-colour images (clip art) would otherwise give GrabCut's
        # colour GMMs zero-variance components that claim the whole rectangle
        dither = np.random.default_rng(0).normal(0.0, 2.0, photo_bgr.shape)
        img = np.clip(photo_bgr + dither, 0, 255).astype(np.uint8)
        cv2.setRNGSeed(0)  # GrabCut's GMM initialisation uses OpenCV's RNG: keep it reproducible
        cv2.grabCut(img, gc, (x, y, w, h), bgd, fgd, 5, cv2.GC_INIT_WITH_RECT)
        fg = (gc == cv2.GC_FGD) | (gc == cv2.GC_PR_FGD)
    else:
        bg_like = _background_like(photo_bgr, params, hsv)
        # grow inward: background = background-like pixels connected to the photo's border
        pad = np.pad(bg_like, 1, constant_values=True).astype(np.uint8)
        _, lab = cv2.connectedComponents(pad, connectivity=4)
        fg = lab[1:-1, 1:-1] != lab[0, 0]
    mask = _largest_filled(fg)
    area = int(np.count_nonzero(mask))
    if area < _MIN_TARGET_PX or area > _MAX_TARGET_FRAC * H * W:
        how = "inside the ROI" if roi is not None else "against the border's background (try --roi X,Y,W,H)"
        raise InputError(f"photo: no separable target {how}")
    return mask


def circular_median(hues: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Circular median of hue samples along the last axis (OpenCV hue, 0..179): the sample
    minimising the sum of circular distances to the other valid samples. Rows with no valid
    sample get NO_HUE. hues, valid: (N, K)."""
    d = hue_distance(hues[:, :, None], hues[:, None, :]).astype(np.int32)  # (N, K, K)
    d = np.where(valid[:, None, :], d, 0).sum(axis=2)
    d = np.where(valid, d, np.iinfo(np.int32).max)
    best = np.take_along_axis(hues, np.argmin(d, axis=1)[:, None], axis=1)[:, 0].astype(np.uint8)
    return np.where(valid.any(axis=1), best, NO_HUE).astype(np.uint8)


def _grid(origin: tuple[float, float], interval: float, x0: float, x1: float, y0: float, y1: float
          ) -> np.ndarray:
    """Grid points (x, y) px anchored on the model origin, spanning [x0, x1] x [y0, y1]."""
    kx = np.arange(np.floor((x0 - origin[0]) / interval), np.ceil((x1 - origin[0]) / interval) + 1)
    ky = np.arange(np.floor((y0 - origin[1]) / interval), np.ceil((y1 - origin[1]) / interval) + 1)
    gx, gy = np.meshgrid(origin[0] + kx * interval, origin[1] + ky * interval)
    return np.column_stack([gx.ravel(), gy.ravel()])


def _sample(photo_hue: np.ndarray, mask: np.ndarray, origin: tuple[float, float], interval: float,
            band: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inner points (with their hue) and outer points on one grid of pitch `interval` px."""
    H, W = mask.shape
    # inner: grid points on the target; each carries the circular median hue of its neighbourhood
    ys, xs = np.nonzero(mask)
    pts = _grid(origin, interval, xs.min(), xs.max(), ys.min(), ys.max())
    ij = np.rint(pts).astype(int)
    inside = (ij[:, 0] >= 0) & (ij[:, 0] < W) & (ij[:, 1] >= 0) & (ij[:, 1] < H)
    ij = np.clip(ij, 0, [W - 1, H - 1])  # a target touching the photo's edge: grid points past it are off
    on = inside & (mask[ij[:, 1], ij[:, 0]] > 0)
    pin = pts[on]
    r = int(np.clip(round(interval / 2), 1, 3))
    off = np.arange(-r, r + 1)
    ox, oy = np.meshgrid(off, off)
    cx = np.clip(np.rint(pin[:, 0:1]).astype(int) + ox.ravel()[None], 0, W - 1)
    cy = np.clip(np.rint(pin[:, 1:2]).astype(int) + oy.ravel()[None], 0, H - 1)
    hs = photo_hue[cy, cx]
    valid = (hs != NO_HUE) & (mask[cy, cx] > 0)
    hue = circular_median(hs.astype(np.int16), valid)
    keep = hue != NO_HUE  # a point whose neighbourhood carries no hue cannot score: dropped
    # outer: grid points off the target within `band` px of it (the photo is padded so the band
    # may extend past the photo's edge)
    p = int(np.ceil(band)) + 2
    outside = np.pad(mask == 0, p, constant_values=True).astype(np.uint8)
    dist = cv2.distanceTransform(outside, cv2.DIST_L2, 5)
    pts = _grid(origin, interval, xs.min() - band, xs.max() + band, ys.min() - band, ys.max() + band)
    ij = np.rint(pts).astype(int) + p
    ij[:, 0] = np.clip(ij[:, 0], 0, W + 2 * p - 1)
    ij[:, 1] = np.clip(ij[:, 1], 0, H + 2 * p - 1)
    dd = dist[ij[:, 1], ij[:, 0]]
    # keep half a pitch (>= 1.5 px) clear of the outline, where the hue is ambiguous
    pout = pts[(dd >= max(1.5, 0.5 * interval)) & (dd <= band)]
    return pin[keep], hue[keep], pout


def build_photo_model(photo_bgr: np.ndarray, params: PhotoModelParams,
                      roi: tuple[int, int, int, int] | None = None) -> PhotoModel:
    """Method steps 1-2: the photo-model of one photo (BGR uint8).

    The target is cut out by `target_mask` (border-inward hue scan, or GrabCut inside `roi`).
    Sampling points lie on one grid of pitch `params.interval_px` anchored at the model origin
    (the centre of the target's bounding rectangle): inner points S_in on the target, each with
    the circular median hue of its small neighbourhood (points whose neighbourhood carries no hue
    are dropped), and outer points S_out off the target within `params.band_px` of it, or
    `params.band_frac` of the target's longest side when that is less (a small photo, such as a
    target cut from a distant view, would otherwise weigh its outline far above its body:
    its ratio of outer to inner points would grow as the photo shrinks). Above
    `params.max_points` points the pitch is coarsened until they fit. `target_hues` marks the
    hues of the inner points and of every hue holding >= 1 % of the target's hued pixels,
    widened by `params.hue_tolerance`. `inner_value` holds the photo's grey at each inner point
    (`sampling.photo_values`), `inner_brightness` its brightness, `inner_saturation` its saturation,
    `colour_cells` the photo's colours over hue and saturation (`hs_cells.photo_cells`).

    Raises InputError when the photo is not a colour image, no target separates, or the target
    carries no hue (all grey/white/dark)."""
    photo_bgr = _check_photo(photo_bgr)
    hsv = cv2.cvtColor(photo_bgr, cv2.COLOR_BGR2HSV)  # once: the mask's scan, the hues, saturations and cells read it
    mask = target_mask(photo_bgr, params, roi, hsv)
    hue = _hsv_hue(hsv, params.min_saturation, params.min_value)
    x, y, w, h = cv2.boundingRect(mask)
    origin = (x + (w - 1) / 2.0, y + (h - 1) / 2.0)
    interval = float(params.interval_px)
    band = min(float(params.band_px), params.band_frac * max(w, h))
    for _ in range(50):
        pin, hin, pout = _sample(hue, mask, origin, interval, band)
        if len(pin) + len(pout) <= params.max_points:
            break
        interval *= max(1.02, float(np.sqrt((len(pin) + len(pout)) / params.max_points)))
    if len(pin) < 3:
        raise InputError("photo: the target carries no hue (too grey, white or dark for the "
                         f"saturation/value floors {params.min_saturation}/{params.min_value})")
    th = hue[mask > 0]
    th = th[th != NO_HUE]
    hist = np.bincount(th, minlength=HUE_BINS)[:HUE_BINS]
    present = (hist >= 0.01 * max(1, th.size))
    present[hin] = True
    lut = np.zeros(HUE_BINS, bool)
    for k in np.flatnonzero(present):
        lut[(k + np.arange(-params.hue_tolerance, params.hue_tolerance + 1)) % HUE_BINS] = True
    o = np.array(origin)
    return PhotoModel(inner_uv=pin - o, inner_hue=hin.astype(np.uint8), outer_uv=pout - o,
                      target_hues=lut, size_px=(float(w), float(h)), origin_px=origin, mask=mask,
                      inner_value=photo_values(photo_bgr, pin, interval),
                      inner_brightness=photo_values(photo_bgr, pin, interval, brightness),
                      inner_saturation=plane_values(hsv[..., 1].astype(np.float32), pin, interval),
                      colour_cells=photo_cells(photo_bgr, mask, params.min_value, hsv))


def load_photo_model(path: str, params: PhotoModelParams,
                     roi: tuple[int, int, int, int] | None = None) -> PhotoModel:
    """Read a photo file and build its photo-model; errors name the file."""
    from photoservo.fileio import read_image

    photo = read_image(path, "photo")
    try:
        return build_photo_model(photo, params, roi)
    except InputError as e:
        msg = str(e)
        raise InputError(f"{path}: {msg.removeprefix('photo: ')}") from None


def draw_photo_model(photo_bgr: np.ndarray, model: PhotoModel, scale: int = 2) -> np.ndarray:
    """Preview (BGR uint8, `scale` times the photo): the target outline in yellow, inner points
    filled with their own hue ringed in white, outer points as small black-ringed grey dots, the
    origin as a cross."""
    s = int(max(1, scale))
    img = cv2.resize(photo_bgr, None, fx=s, fy=s, interpolation=cv2.INTER_NEAREST)
    img = (0.6 * img + 0.4 * 255).astype(np.uint8)  # fade the photo so the points stand out
    contours, _ = cv2.findContours(model.mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(img, [c * s for c in contours], -1, (0, 200, 255), 1, cv2.LINE_AA)
    o = np.array(model.origin_px)
    sh = 4  # fixed-point bits for sub-pixel drawing
    def px(uv: np.ndarray) -> np.ndarray:
        return np.rint(((uv + o) * s + (s - 1) / 2) * (1 << sh)).astype(int)
    hsv = np.stack([model.inner_hue, np.full_like(model.inner_hue, 255), np.full_like(model.inner_hue, 230)], -1)
    cols = cv2.cvtColor(hsv[None].astype(np.uint8), cv2.COLOR_HSV2BGR)[0]
    r = max(2, s + 1)
    for p, c in zip(px(model.inner_uv), cols):
        cv2.circle(img, tuple(p), r << sh, tuple(int(v) for v in c), -1, cv2.LINE_AA, sh)
        cv2.circle(img, tuple(p), r << sh, (255, 255, 255), 1, cv2.LINE_AA, sh)
    for p in px(model.outer_uv):
        cv2.circle(img, tuple(p), (r - 1) << sh, (60, 60, 60), -1, cv2.LINE_AA, sh)
    c = tuple(int(v) for v in px(np.zeros((1, 2)))[0])
    cv2.drawMarker(img, (c[0] >> sh, c[1] >> sh), (0, 0, 255), cv2.MARKER_CROSS, 6 * s, 2)
    return img
