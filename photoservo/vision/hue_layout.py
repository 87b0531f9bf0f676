"""Seeds from where the photo's hue layout agrees (issue 9, many-hued creatures): no assumption
that the creature's hues are absent from the water or the background.

A creature painted in many hues (a wrasse or a parrotfish: blue and green among them) has the
water's hue among its `target_hues`, so the target-hue blobs of `vision/seeding.py` cover the
water and seed nothing. What still sets the creature apart is that, in a window of its size, its
hues occur in the proportions the photo shows. For every hue bin b (soft-binned, `BINS` bins) the
photo-model's inner points give the share p_b of the creature in that hue; in the image, a box of
side d (the side of a square as large as the creature at apparent scale s: d = s·sqrt(area)) over
pixel x holds c_b(x) pixels of hue b, and

    A(x, d) = sum_b min(c_b(x), p_b d^2) / d^2        (histogram intersection, 0..1)

is the share of the creature's hue proportions found there. Over water A is the creature's own
share of the water's hue; at the creature (centred, right scale) it is near 1 less what foam or
glare hides. A is rotation-invariant, cheap (box filters on a quarter-size image, a few scales) and
its maxima over (x, d) give the hue centroid and apparent size of what agrees with the photo;
maxima in the two images are paired along the epipolar lines like blobs (`match_blobs`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import cv2
import numpy as np

from photoservo.vision.photo_model import HUE_BINS, PhotoModel
from photoservo.vision.rig import Rig
from photoservo.vision.seeding import Blob, BlobPair, match_blobs

if TYPE_CHECKING:
    from photoservo.vision.estimator import EstimatorParams

BINS = 18  # hue bins of 10 OpenCV steps (20 deg), soft-assigned
_DOWN = 4  # the layout is computed on a quarter-size image
GROW_AGREEMENT = 0.97  # a peak's grown box: the largest side agreeing at least this share as well (agreement_peaks)
GROW_SAME = 0.7  # no grown box where a peak of at least this share of its side lies already
GROWN_ISLANDS = 2  # at most this many grown boxes' pairs seed islands of their own (layout_pairs)


def hue_shares(hues: np.ndarray) -> np.ndarray:
    """Soft histogram (BINS,) of OpenCV hues 0..179 (NO_HUE ignored), summing to 1 (zeros if none)."""
    h = np.asarray(hues, np.float64).ravel()
    h = h[h < HUE_BINS]
    out = np.zeros(BINS)
    if not len(h):
        return out
    x = h / (HUE_BINS / BINS) - 0.5
    lo = np.floor(x)
    w = x - lo
    np.add.at(out, lo.astype(int) % BINS, 1 - w)
    np.add.at(out, (lo.astype(int) + 1) % BINS, w)
    return out / len(h)


def _soft_planes(hue: np.ndarray) -> np.ndarray:
    """(BINS, H, W) float32: each pixel's soft membership of every hue bin (NO_HUE: none)."""
    h = hue.astype(np.float32)
    valid = hue < HUE_BINS
    x = h / (HUE_BINS / BINS) - 0.5
    lo = np.floor(x)
    w = (x - lo).astype(np.float32)
    lo_i = np.where(valid, lo.astype(np.int32) % BINS, -1)
    hi_i = np.where(valid, (lo.astype(np.int32) + 1) % BINS, -1)
    planes = np.zeros((BINS, *hue.shape), np.float32)
    for b in range(BINS):
        planes[b] = np.where(lo_i == b, 1 - w, 0) + np.where(hi_i == b, w, 0)
    return planes


def agreement_peaks(hue: np.ndarray, shares: np.ndarray, sides_px: np.ndarray, max_peaks: int = 6
                    ) -> tuple[list[tuple[float, float, float, float]], list[tuple[float, float, float, float]]]:
    """Maxima of A(x, d) (module docstring) over the image and the box sides `sides_px` (full
    resolution px): (peaks, grown). `peaks`: [(u, v, d, A)], best first, at most `max_peaks`, each
    at least half its side from a better one; only peaks clearly above the image's typical
    agreement (its median plus half the way to the best).

    `grown`: for each peak, best first, the largest side d' whose best A within d'/2 of it is at
    least `GROW_AGREEMENT` of the peak's own, at that best place, where d' > d; each at least half
    its side from a grown box before it and not where a peak of at least `GROW_SAME` of its side
    already lies. Inside a single-hued target a small box agrees best (its hues the photo's main
    one, without the shading at the rim): Middlebury's aloe pot had its four peaks at a side of
    30 px (the pot 142 px), every island's window reaching 2x, every fit 3-8x too small. A larger
    side that agrees as well nearby estimates the size better, but moving the peak there lost
    others (the motorcycle's crate: a grown box matched at another depth suppressed the crate's
    second peak), so the grown boxes are seeds beside the peaks, not in their place."""
    small = cv2.resize(hue, (hue.shape[1] // _DOWN, hue.shape[0] // _DOWN), interpolation=cv2.INTER_NEAREST)
    planes = _soft_planes(small)
    best = np.full(small.shape, -1.0, np.float32)
    best_d = np.zeros(small.shape, np.float32)
    maps = []  # (d, box side in small px, A) per side
    for d in sides_px:
        k = max(3, int(round(d / _DOWN)) | 1)
        area = float(k * k)
        A = np.zeros(small.shape, np.float32)
        for b in range(BINS):
            if shares[b] <= 1e-3:
                continue
            c = cv2.boxFilter(planes[b], -1, (k, k), normalize=False, borderType=cv2.BORDER_CONSTANT)
            A += np.minimum(c, np.float32(shares[b] * area))
        A /= area
        maps.append((float(d), k, A))
        # a larger box that agrees as well is the better estimate of the size (a single-hued
        # creature agrees with any box inside it)
        take = A >= best * 0.97
        best = np.where(take, A, best)
        best_d = np.where(take, d, best_d)
    med, top = float(np.median(best)), float(best.max())
    floor = med + 0.5 * (top - med)
    peaks: list[tuple[float, float, float, float]] = []
    order = np.argsort(-best, axis=None)
    for idx in order[: 4096]:
        y, x = np.unravel_index(idx, best.shape)
        a = float(best[y, x])
        if a < floor or len(peaks) >= max_peaks:
            break
        u, v, d = (x + 0.5) * _DOWN - 0.5, (y + 0.5) * _DOWN - 0.5, float(best_d[y, x])
        if all(math.hypot(u - pu, v - pv) >= 0.5 * max(d, pd) for pu, pv, pd, _ in peaks):
            peaks.append((u, v, d, a))
    grown: list[tuple[float, float, float, float]] = []
    for pu, pv, pd, a in peaks:
        x, y = int(round((pu + 0.5) / _DOWN - 0.5)), int(round((pv + 0.5) / _DOWN - 0.5))
        box = None
        for d2, k2, A2 in maps:
            if d2 <= pd:
                continue
            r = max(1, k2 // 2)
            y0, x0 = max(0, y - r), max(0, x - r)
            near = A2[y0:y + r + 1, x0:x + r + 1]
            j = np.unravel_index(int(np.argmax(near)), near.shape)
            if near[j] >= GROW_AGREEMENT * a:
                box = ((x0 + j[1] + 0.5) * _DOWN - 0.5, (y0 + j[0] + 0.5) * _DOWN - 0.5, d2, float(near[j]))
        if box is None:
            continue
        u, v, d, _ = box
        if all(math.hypot(u - gu, v - gv) >= 0.5 * max(d, gd) for gu, gv, gd, _ in grown) and \
                not any(math.hypot(u - qu, v - qv) < 0.5 * max(d, qd) and qd >= GROW_SAME * d for qu, qv, qd, _ in peaks):
            grown.append(box)
    return peaks, grown


def layout_pairs(hue_left: np.ndarray, hue_right: np.ndarray, model: PhotoModel, model_area_px: float,
                 rig: Rig, params: EstimatorParams) -> tuple[list[BlobPair], list[BlobPair]]:
    """Seed pairs from the hue-layout agreement: (pairs, grown). `pairs`: peaks of A in each image
    at box sides from `min_apparent_px` to half the image height, paired along the epipolar lines
    and triangulated by `match_blobs` (each peak as a round blob of area d^2: the apparent area of
    the model). `grown`: at most `GROWN_ISLANDS` pairs of the left image's grown boxes
    (`agreement_peaks`) with the right image's grown boxes or peaks, extra seeds beside `pairs`."""
    shares = hue_shares(model.inner_hue)
    lo = max(params.min_apparent_px, 8.0) * math.sqrt(model_area_px) / max(model.size_px)
    hi = 0.5 * rig.left.height
    sides = np.geomspace(lo, max(hi, lo * 1.5), 7)

    def blobs(peaks: list[tuple[float, float, float, float]]) -> list[Blob]:
        return [Blob(centroid=np.array([u, v]), area=d * d, angle=0.0, elongation=1.0,
                     mu=(d * d / 12.0, d * d / 12.0, 0.0))
                for u, v, d, _ in peaks]
    (left, left_grown), (right, right_grown) = (agreement_peaks(h, shares, sides) for h in (hue_left, hue_right))
    pairs = match_blobs(blobs(left), blobs(right), rig, params)
    grown = match_blobs(blobs(left_grown), blobs(right_grown + right), rig, params) if left_grown else []
    return pairs, grown[:GROWN_ISLANDS]
