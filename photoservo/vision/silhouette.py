"""Seeds from where the photo's silhouette fits the pair's distinctive hues (issue 9, real images:
the creature's hues also cover the background).

On a real photo the target's hues (`target_hues`: its inner hues widened by the hue tolerance)
often cover much of the scene as well: a red object's shading runs into orange, and a garage's
wood and floor are orange. Target-hue blobs then merge the object with the background, and the
hue layout (`vision/hue_layout.py`) agrees anywhere on a single-hued region. Two things still
set the object apart, both measured on the pair at hand, with no level fitted to a scene:

1. **Distinctive hues** (`distinctive_weight`): a hue the creature holds a larger share of than
   the frame does. With M(h) the photo-model's inner points' hue distribution and I(h) the
   pair's hued pixels' (both smoothed over a few hue steps), a pixel of hue h weighs

       w(h) = M(h) / (M(h) + I(h))        (0..1; > 1/2: more the creature's than the frame's)

   and only target hues weigh at all. Wood that merely lies within the hue tolerance of a red
   object's shading weighs ~0; the object's own red weighs ~0.9.
2. **The silhouette** (`silhouette_peaks`): the photo's target mask, scaled by s and turned by
   psi, laid on the weight image as a template: its score is the mean weight inside the mask
   minus the mean weight in a ring around it (the inner and outer points of method step 3 on the
   weights, in one image). A template too small inside a larger region of the same hue scores
   ~0 (its ring is covered too), one too large loses inside, so the peaks over (u, v, s, psi)
   give where, how large and at which heading something shaped like the photo is.

Peaks of each image become round-free `Blob`s (centroid, area s^2 * mask area, the turned
mask's axis) and are paired along the epipolar lines by `match_blobs`, like target-hue blobs.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import cv2
import numpy as np

from photoservo.vision.photo_model import HUE_BINS, PhotoModel, hue_distance
from photoservo.vision.rig import Rig, project_points
from photoservo.vision.seeding import Blob, BlobPair, ModelShape, match_blobs

if TYPE_CHECKING:
    from photoservo.vision.estimator import EstimatorParams

_SMOOTH = 3  # hue histograms are smoothed by a triangle of this half-width (OpenCV hue steps)
_HEADINGS = 12  # template headings over 180 deg (the GA's seeds try psi and psi + 180 deg)
_SCALE_STEP = 2.0 ** 0.25  # template scales: apparent size grows by this factor per step
_DOWN = 4.0  # the weight image is shrunk at least this much
_TEMPLATE_PX = 24.0  # templates are matched at about this longest side (px), the image shrunk to suit


def _hue_density(hues: np.ndarray) -> np.ndarray:
    """(HUE_BINS,) distribution of hues (NO_HUE ignored), smoothed by a circular triangle."""
    h = np.asarray(hues).ravel()
    h = h[h < HUE_BINS]
    c = np.bincount(h, minlength=HUE_BINS)[:HUE_BINS].astype(np.float64) / max(len(h), 1)
    d = hue_distance(np.arange(HUE_BINS)[:, None], np.arange(HUE_BINS)[None, :]).astype(np.float64)
    k = np.clip(1.0 - d / (_SMOOTH + 1), 0.0, None)
    return (k / k.sum(axis=1, keepdims=True)) @ c


def distinctive_weight(hue_left: np.ndarray, hue_right: np.ndarray, model: PhotoModel) -> np.ndarray:
    """(256,) float32 lookup: weight w(h) of every hue value (module docstring, item 1); 0 for
    hues that are not target hues and for NO_HUE."""
    M = _hue_density(model.inner_hue)
    I_ = 0.5 * (_hue_density(hue_left) + _hue_density(hue_right))
    w = np.where(np.asarray(model.target_hues, bool), M / np.maximum(M + I_, 1e-12), 0.0)
    lut = np.zeros(256, np.float32)
    lut[:HUE_BINS] = w
    return lut


def _templates(mask: np.ndarray, side_px: float, psi: float) -> tuple[np.ndarray, tuple[float, float], float]:
    """The template of the photo mask turned by psi (rad) with its longest side `side_px` px:
    (T, centroid offset of the turned mask within T (px), turned mask area (px)). T is +1/n_in on
    the mask and -1/n_ring on a ring around it (its width a tenth of the side, at least 1 px)."""
    h, w = mask.shape
    s = side_px / max(h, w)
    ring = max(1, int(round(0.1 * side_px)))
    c, si = math.cos(psi), math.sin(psi)
    # the turned, scaled mask's bounding box (+ ring) and the affine map into it
    corners = np.array([[0, 0], [w, 0], [0, h], [w, h]], np.float64) - (w / 2, h / 2)
    rot = np.array([[c, -si], [si, c]]) * s
    ext = np.abs(corners @ rot.T).max(axis=0)
    W = int(math.ceil(2 * ext[0])) + 2 * ring + 2
    H = int(math.ceil(2 * ext[1])) + 2 * ring + 2
    A = np.hstack([rot, (np.array([W / 2, H / 2]) - rot @ (w / 2, h / 2))[:, None]])
    inner = cv2.warpAffine((mask > 0).astype(np.uint8) * 255, A, (W, H), flags=cv2.INTER_AREA) >= 128
    if not inner.any():
        return np.zeros((0, 0), np.float32), (0.0, 0.0), 0.0
    outer = cv2.dilate(inner.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * ring + 1,) * 2)) > 0
    outer &= ~inner
    T = np.zeros((H, W), np.float32)
    T[inner] = 1.0 / inner.sum()
    if outer.any():
        T[outer] = -1.0 / outer.sum()
    ys, xs = np.nonzero(inner)
    return T, (float(xs.mean()), float(ys.mean())), float(inner.sum())


def _level(side_px: float) -> float:
    """Downsampling factor for a template of apparent longest side `side_px`: the template is
    matched at about `_TEMPLATE_PX` px, on an image shrunk at least `_DOWN` times (spots a few
    pixels wide, which any small template fits perfectly, blur away)."""
    return max(_DOWN, side_px / _TEMPLATE_PX)


def _shrunk(weight: np.ndarray, f: float) -> np.ndarray:
    return cv2.resize(weight, (max(1, round(weight.shape[1] / f)), max(1, round(weight.shape[0] / f))),
                      interpolation=cv2.INTER_AREA)


def silhouette_peaks(weight: np.ndarray, mask: np.ndarray, sides_px: np.ndarray, max_peaks: int = 6
                     ) -> list[tuple[float, float, float, float, float, float]]:
    """Best placements of the photo mask on a weight image (full-resolution px; module
    docstring, item 2): [(u, v, area, psi, score, side)] of the mask's centroid, its area (px),
    heading (rad) and the template's longest side (px), best first, at most `max_peaks`, each at
    least half its size from a better one, only scores above zero and above half the best. Each
    side is matched on the image shrunk so that the template is about `_TEMPLATE_PX` px long."""
    found: list[tuple[float, float, float, float, float, float]] = []
    for side in sides_px:
        f = _level(side)
        small = _shrunk(weight, f)
        maps = []
        for k in range(_HEADINGS):
            psi = math.pi * k / _HEADINGS
            T, c, area = _templates(mask, side / f, psi)
            if area >= 4 and T.shape[0] < small.shape[0] and T.shape[1] < small.shape[1]:
                maps.append((psi, c, area, cv2.matchTemplate(small, T, cv2.TM_CCORR)))
        if not maps:
            continue
        for psi, (cx, cy), area, r in maps:
            mx = cv2.dilate(r, np.ones((3, 3), np.uint8))  # local maxima (3x3)
            ys, xs = np.nonzero((r >= mx) & (r > 0))
            top = np.argsort(-r[ys, xs])[: 2 * max_peaks]
            for y, x in zip(ys[top], xs[top]):
                found.append(((x + cx + 0.5) * f - 0.5, (y + cy + 0.5) * f - 0.5, area * f * f, psi,
                              float(r[y, x]), float(side)))
    found.sort(key=lambda p: -p[4])
    peaks: list[tuple[float, float, float, float, float, float]] = []
    for p in found:
        if p[4] < 0.5 * found[0][4] or len(peaks) >= max_peaks:
            break
        if all(math.hypot(p[0] - q[0], p[1] - q[1]) >= 0.5 * math.sqrt(max(p[2], q[2])) for q in peaks):
            peaks.append(p)
    return peaks


def epipolar_match(weight_left: np.ndarray, weight_right: np.ndarray, mask: np.ndarray, peak: tuple, rig: Rig,
                   params: EstimatorParams) -> tuple[float, float] | None:
    """Where the left peak's patch of weights (under its template's footprint, at the template's
    level) fits best in the right weight image (normalised cross-correlation) along the left
    centroid's line of sight, between z_min_mm and z_max_mm (and within epipolar_tol_px of it):
    the right centroid (px), or None when the patch leaves either image or is flat."""
    u, v, _, psi, _, side = peak
    f = _level(side)
    left, right = _shrunk(weight_left, f), _shrunk(weight_right, f)
    T, (cx, cy), _ = _templates(mask, side / f, psi)
    x0, y0 = int(round((u + 0.5) / f - 0.5 - cx)), int(round((v + 0.5) / f - 0.5 - cy))
    th, tw = T.shape
    if x0 < 0 or y0 < 0 or x0 + tw > left.shape[1] or y0 + th > left.shape[0] or th >= right.shape[0] \
            or tw >= right.shape[1]:
        return None
    patch = left[y0:y0 + th, x0:x0 + tw]
    if float(patch.std()) < 1e-3:
        return None
    r = cv2.matchTemplate(right, patch, cv2.TM_CCOEFF_NORMED)
    K = rig.left.K
    ray = np.array([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], 1.0])
    q = np.linspace(1.0 / params.z_max_mm, 1.0 / params.z_min_mm, 400)
    uv = project_points((ray[None] / q[:, None]) @ rig.R.T + rig.T, rig.right)
    tol = max(1, int(round(params.epipolar_tol_px / f)))
    best, at = -np.inf, None
    for dy in range(-tol, tol + 1):
        x = np.rint((uv[:, 0] + 0.5) / f - 0.5 - cx).astype(int)
        y = np.rint((uv[:, 1] + 0.5) / f - 0.5 - cy).astype(int) + dy
        ok = (x >= 0) & (x < r.shape[1]) & (y >= 0) & (y < r.shape[0])
        if not ok.any():
            continue
        vals = r[y[ok], x[ok]]
        i = int(np.argmax(vals))
        if vals[i] > best:
            best, at = float(vals[i]), ((x[ok][i] + cx + 0.5) * f - 0.5, (y[ok][i] + cy + 0.5) * f - 0.5)
    return at if best > 0 else None


def _blob(u: float, v: float, area: float, psi: float, shape: ModelShape) -> Blob:
    """A Blob for the photo mask placed with its centroid at (u, v), `area` px, turned by psi:
    its second moments are the mask's equivalent ellipse's, turned with it."""
    a2 = shape.angle + psi
    e = shape.elongation
    l2 = area / (4 * math.pi * e)
    l1 = l2 * e * e
    c, s = math.cos(a2), math.sin(a2)
    return Blob(centroid=np.array([u, v]), area=area, angle=math.atan2(s, c), elongation=e,
                mu=(l1 * c * c + l2 * s * s, l1 * s * s + l2 * c * c, (l1 - l2) * s * c))


def silhouette_pairs(hue_left: np.ndarray, hue_right: np.ndarray, model: PhotoModel, rig: Rig,
                     params: EstimatorParams) -> list[BlobPair]:
    """Seed pairs: the silhouette peaks of the left image on the distinctive-hue weights, each
    matched in the right image along its line of sight (`epipolar_match`: the left image's own
    weights there, more telling than the silhouette alone) and triangulated by
    `match_blobs`; best left score first. Template sides (the apparent longest side) from
    `min_apparent_px` to 0.6 of the image height."""
    lut = distinctive_weight(hue_left, hue_right, model)
    shape = ModelShape.of(model)
    mask = np.asarray(model.mask) > 0
    lo = max(params.min_apparent_px, 4.0 * _DOWN)
    hi = max(0.6 * rig.left.height, lo * 1.5)
    sides = lo * _SCALE_STEP ** np.arange(int(math.log(hi / lo) / math.log(_SCALE_STEP)) + 1)
    w_left, w_right = lut[hue_left], lut[hue_right]
    pairs = []
    for peak in silhouette_peaks(w_left, mask, sides):
        at = epipolar_match(w_left, w_right, mask, peak, rig, params)
        if at is None:
            continue
        u, v, area, psi = peak[:4]
        pairs += match_blobs([_blob(u, v, area, psi, shape)], [_blob(*at, area, psi, shape)], rig, params)
    return pairs
