"""Are all of the creature's parts there? The detection's check that the hue agreement of a
candidate is spread over the whole photo-model, not gathered on part of it.

The fitness (method step 3) sums the inner points S_in that land on their own hue. A model of
another shape laid over a look-alike of the creature's colour — a crab's photo-model squeezed
onto a squid's mantle or a buoy — gathers most of that sum on its body while its legs and claws
fall on water: a fitness, a contrast to its null and an outline like a creature's, but whole
parts of the photo-model absent. A creature under foam, glare or a shadow loses parts too, but
there its inner points land on pixels without hue (`NO_HUE`), which say nothing; on water they
land on the water's hue, which says "not here".

So the photo-model's inner points are divided once into `PARTS` compact parts (`model_parts`:
k-means over the points' photo offsets, from a deterministic farthest-point start), and at a
pose, per camera, a part counts when enough of its points land on hue (`MIN_HUED_SHARE` of them,
at least `MIN_POINTS`), and is absent when fewer than half of those land on one of the target's
hues (`PhotoModel.target_hues`: any hue of the photo, within the tolerance):

    absent_c = #(parts counted in camera c with on_target / hued < 1/2) / #(parts of the model)
    absent   = max over the cameras that count any part                      (0..1; nan if none)

Over all of the model's parts, not over those counted: a part under foam or glare is not absent,
and so does not make the others weigh more either. (Over the counted parts, a squid from another
individual's photo with a third of its parts under a foam band had its two arm tips — 3 and 5
hued points of ~180, held elsewhere than the photo's — count as 2 of 8 = 0.25 and was rejected,
renderer scene 1009; 2 of 12 now. Every look-alike the check rejects on both generators' 100 null
scenes has all 12 parts counted in both cameras, so its share is the same either way.)

Any target hue, not the point's own: the light shifts the hue across a real body (a shaded
flank, a gilded highlight) and moves a part's points onto the creature's other hues, not onto
the water's; on the harbour generator the point's own hue called a third to a half of a lit
squid's or crab's parts absent at the true pose. Each part is judged against itself (a share of
its own hued points), so the decision does not rest on a fitness level of one renderer. Where
the water carries one of the target's hues (a many-hued fish) parts on water count as present:
the check then lets through what it cannot judge. Detection (`vision/detection.py`) rejects a
candidate with `absent` above `[estimator] max_absent_parts`.

Foam has an edge, and the edge has hue. A foam band over a creature ends in ragged, blurred
bubbles: beside the white, the creature's colour and the water's mixed with it, pale hues; a
part straddling the band's edge has most of its points on hue there, few on the target's, and
counts as absent though the creature is there under it (renderer held-out 1211, 1225, 1234: fits
within 2-3.4 % of the truth rejected with 2-3 of 12 parts absent, one or two at the band). Foam
is measurable in the pair itself: pixels without hue at least as bright as the median of the
image's hued pixels (the water, mostly; shadow is darker; glare is as white and is treated
alike), in patches (a creature's one-pixel pale rim is not foam). `foam_marked` marks them FOAM
in the hue frame the parts check reads (vision/detection.py; the fitness, the contrast and the
outline read the pair as it is). Where the model lies under foam (`under_foam`: at least
`[estimator] foam_part_share` of its inner points on foam in both cameras, as a band across the
creature puts them; glare and sun glitter beside a look-alike put few there) a part with at
least that share of its points on foam is not judged:

    absent_c(part) = counted and on_target / hued < 1/2
                     and not (under_foam and on_foam(part) / size(part) >= foam_part_share)

Frames: inner points in photo px offsets (`PhotoModel.inner_uv`); poses as in `fitness`.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from photoservo.vision.fitness import ModelProjection, StereoHue, inner_hues, nearest_pixel, project_model
from photoservo.vision.photo_model import HUE_BINS, NO_HUE, PhotoModel, target_hue_lut
from photoservo.vision.rig import Rig

PARTS = 12  # parts of the photo-model (a crab's body, claws and leg groups; a fish's head, fins, tail)
MIN_HUED_SHARE = 0.3  # a part counts in a camera when at least this share of its points land on hue...
MIN_POINTS = 3  # ...and at least this many
FOAM = 254  # `foam_marked`: a pixel without hue that is foam (or glare): white
# ...in a patch at least this wide: a morphological opening by a 3 x 3 disc drops the one-pixel pale
# rim a creature's outline blends into the water (renderer look-alike null 1847: a crab's model on
# a fish, 4 of 12 parts absent, 2 when its rim counted as foam)
FOAM_OPENING = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))


def model_parts(inner_uv: np.ndarray, n_parts: int = PARTS, iterations: int = 30) -> np.ndarray:
    """(N_in,) int part label of each inner point: k-means (Lloyd) over the photo offsets uv
    (N_in, 2) px into min(n_parts, N_in) compact parts, started from the point nearest the
    centroid and then each point farthest from the centres so far (deterministic)."""
    uv = np.asarray(inner_uv, dtype=np.float64).reshape(-1, 2)
    n = min(n_parts, len(uv))
    if n == 0:
        return np.zeros(0, np.intp)
    first = int(np.argmin(((uv - uv.mean(axis=0)) ** 2).sum(axis=1)))
    centres = [uv[first]]
    d = ((uv - centres[0]) ** 2).sum(axis=1)
    for _ in range(1, n):
        centres.append(uv[int(np.argmax(d))])
        d = np.minimum(d, ((uv - centres[-1]) ** 2).sum(axis=1))
    C = np.array(centres)
    labels = np.zeros(len(uv), np.intp)
    for _ in range(iterations):
        labels = ((uv[:, None, :] - C[None]) ** 2).sum(axis=-1).argmin(axis=1)
        counts = np.bincount(labels, minlength=n)
        sums = np.stack([np.bincount(labels, weights=uv[:, k], minlength=n) for k in (0, 1)], axis=1)
        new = np.where(counts[:, None] > 0, sums / np.maximum(counts, 1)[:, None], C)
        if np.allclose(new, C):
            break
        C = new
    return labels


def absent_flags(hued: np.ndarray, on_target: np.ndarray, labels: np.ndarray,
                 foam: np.ndarray | None = None, foam_share: float = 1.0) -> np.ndarray:
    """(C, n_parts) bool: the parts absent in each camera (module docstring) from per-camera
    (C, N_in) bool arrays `hued` (the point lands on a pixel with hue) and `on_target` (...on a
    target hue) and the part `labels` (`model_parts`): counted (enough of its points on hue) and
    fewer than half of those on a target hue — and, with `foam` ((C, N_in) bool: the point lands
    on foam, `foam_marked`) where the model lies under foam (`under_foam`), fewer than
    `foam_share` of its points on foam (module docstring)."""
    hued = np.atleast_2d(np.asarray(hued, bool))
    agrees = np.atleast_2d(np.asarray(on_target, bool)) & hued
    n = int(labels.max()) + 1 if len(labels) else 0
    size = np.bincount(labels, minlength=n)
    out = np.zeros((len(hued), n), bool)
    for k, (h, a) in enumerate(zip(hued, agrees)):
        nh = np.bincount(labels, weights=h, minlength=n)
        na = np.bincount(labels, weights=a, minlength=n)
        out[k] = counted(nh, size) & (na < 0.5 * nh)
        if foam is not None and under_foam(foam, foam_share):  # a part straddling it: its hued points are its fringe
            out[k] &= np.bincount(labels, weights=np.atleast_2d(foam)[k], minlength=n) < foam_share * size
    return out


def under_foam(foam: np.ndarray, foam_share: float) -> bool:
    """A model lies under foam when at least `foam_share` of its inner points land on foam in every
    camera (`foam` (C, N_in) bool, `foam_marked`): a band across the creature (renderer split
    targets 14-29 %), not glare or sun glitter beside a look-alike (renderer look-alike null 1853,
    a buoy in glitter: 8 % and 3 %, two of its crab model's legs on glitter)."""
    foam = np.atleast_2d(np.asarray(foam, bool))
    return foam.size > 0 and shares_under_foam(foam.mean(axis=1), foam_share)


def shares_under_foam(shares: np.ndarray, foam_share: float) -> bool:
    """`under_foam` from the share of the model's inner points on foam in each camera ((C,),
    `foam_share_inner`'s): at least `foam_share` in every camera."""
    return float(np.min(shares)) >= foam_share


def counted(nh: np.ndarray, size: np.ndarray) -> np.ndarray:
    """(n_parts,) bool: the parts with enough of their `size` points on hue (`nh` of them) to judge."""
    return (nh >= np.maximum(MIN_POINTS, MIN_HUED_SHARE * size)) & (size > 0)


def absent_share(hued: np.ndarray, on_target: np.ndarray, labels: np.ndarray,
                 foam: np.ndarray | None = None, foam_share: float = 1.0) -> float:
    """The share of parts absent (module docstring) from per-camera (C, N_in) bool arrays `hued`
    (the point lands on a pixel with hue) and `on_target` (...on a target hue) and the part
    `labels` (`model_parts`): the worse camera's absent parts over all of the model's parts (those
    without enough hue, under foam or glare, are not absent; nor, with `foam`, those straddling
    foam: `absent_flags`); nan when no camera counts a part."""
    hued = np.atleast_2d(np.asarray(hued, bool))
    n = int(labels.max()) + 1 if len(labels) else 0
    size = np.bincount(labels, minlength=n)
    flags = absent_flags(hued, on_target, labels, foam, foam_share)
    worst = math.nan
    for h, f in zip(hued, flags):
        if not counted(np.bincount(labels, weights=h, minlength=n), size).any():
            continue
        share = float(np.count_nonzero(f)) / int(np.count_nonzero(size))
        worst = share if math.isnan(worst) else max(worst, share)
    return worst


def absent_parts(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, frame: StereoHue, rig: Rig,
                 labels: np.ndarray | None = None, foam_share: float = 1.0, proj: ModelProjection | None = None
                 ) -> float:
    """`absent_share` of one pose: R (3, 3) the model's linear map (`Candidate.R_model`), t (3,)
    mm in the left camera frame, alpha px/mm; `labels` from `model_parts` (computed when None);
    with `frame` from `foam_marked`, a part with at least `foam_share` of its points on foam is
    not judged (module docstring; 1: every part is); `proj`: the pose's `fitness.project_model` (computed
    when None)."""
    h = inner_hues(R, t, alpha, model, frame, rig, proj)
    hued = h < HUE_BINS
    return absent_share(hued, target_hue_lut(model.target_hues)[h], model_parts(model.inner_uv) if labels is None else labels, h == FOAM, foam_share)


def foam_share_inner(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, frame: StereoHue,
                     rig: Rig) -> np.ndarray:
    """(2,) the share of one pose's inner points on foam (`frame` from `foam_marked`) in the left and the
    right camera: points the fitness scores 0 (no hue) where a band of foam hides the creature. R (3, 3)
    the model's linear map, t (3,) mm in the left camera frame, alpha px/mm."""
    return foam_shares(R, t, alpha, model, frame, rig)[0]


def foam_shares(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, model: PhotoModel, frame: StereoHue,
                rig: Rig) -> np.ndarray:
    """(P, 2) `foam_share_inner` of a population: each pose's share of inner points on foam (`frame` from
    `foam_marked`) in the left and the right camera, read as the fitness reads a point (nearest pixel,
    outside the image not on foam). R (P, 3, 3) the models' linear maps, t (P, 3) mm, alpha (P,) px/mm
    (or one pose: (3, 3), (3,), a float)."""
    p = project_model(R, t, alpha, model, rig)
    shares = []
    for uv, marked in ((p.inner_left, frame.left), (p.inner_right, frame.right)):
        r, c, inside = nearest_pixel(uv, marked.shape)
        shares.append(np.mean((marked[r, c] == FOAM) & inside, axis=1))
    return np.stack(shares, axis=1)


def foam_marked(frame: StereoHue, value_left: np.ndarray, value_right: np.ndarray) -> StereoHue:
    """`frame` with its foam marked FOAM (a value without hue, >= HUE_BINS: the fitness never
    reads this frame; the parts check does, module docstring): in each camera the pixels without
    hue at least as bright as the median of the image's hued pixels (the water, mostly; shadow
    is darker) (`value_*`: HSV value 0..255, `sampling.brightness`), opened by `FOAM_OPENING`
    (patches, not a rim). The frame as it is when an image has no hued pixel."""
    out = []
    for hue, value in ((frame.left, value_left), (frame.right, value_right)):
        hued = hue != NO_HUE
        if not hued.any():
            return frame
        marked = hue.copy()
        white = (~hued & (value >= float(np.median(value[hued])))).astype(np.uint8)
        marked[cv2.morphologyEx(white, cv2.MORPH_OPEN, FOAM_OPENING) > 0] = FOAM
        out.append(np.ascontiguousarray(marked))
    return dataclasses.replace(frame, left=out[0], right=out[1])
