"""The contour rule of the stereo fitness (method step 3, extended for issue 9's real images):
where hue cannot bound the target, the colour edge along the photo-model's outline does.

The paper's outer points score when the image hue there is not one of the target's. In a pair
where the target's hues are everywhere — the real pair's garage, whose wood and cardboard lie
within the red's hue tolerance (97-99 % of its hued pixels), or a many-hued creature in water
of one of its hues — every outer point that carries hue lands on a target hue, on the target's
own continuation and on the background alike, and costs w_outer_mismatch either way: the
fitness cannot tell a fit 0.5-0.8x the target (every inner point on it) from the target, and
the crate was found 24-57 % too small. What still tells them apart is in the image itself: an
outer point beyond the target's end sits across a colour edge from the target, one on the
target's continuation does not. Per outer point j and its nearest inner point i(j) in the photo
(`PhotoModel.outer_neighbour`), both projected into camera c, with the image's chroma there
(a*, b* of CIE L*a*b*, OpenCV 8-bit: shading and highlights move L* more than a*b*):

    edge(j) = || ab(outer_j) - ab(inner_i(j)) || > contour_chroma

    on a target hue, edge:      counts as off the target       (OUT_MATCH, + w_outer_match)
    on a target hue, no edge:   the target goes on past the outline there: costs
                                w_outer_match, what an edge earns (OUT_MISMATCH counted
                                w_outer_match / w_outer_mismatch times)
    without hue (grey, dark), edge: off the target             (OUT_MATCH)
    otherwise, or the two less than MIN_GAP_PX apart in the image: the paper's rule.

The rule normalises on the pair at hand: it compares the image with itself at the pose, never
with the photo's colours (the lighting of a photo found on the web is not the scene's). It is
used only where the estimator finds the target's hues over most of the pair
(`estimator.hues_everywhere`, the test that also switches seeding to the hue layout): on water
whose hue is not the target's, the paper's rule already bounds the target. A frame carries the
chroma planes (`StereoHue.chroma`) only there; `fitness` then adds `contour_counts`, and the
outline check (`detection.outer_share`) counts as spill only the outer points on a target hue
without an edge.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np
from numba import njit

from photoservo.vision.fitness_kernel import _FAST, _pixel_indices, _plane_map, _split_points, camera_vector
from photoservo.vision.photo_model import HUE_BINS, NO_HUE, PhotoModel, target_hue_lut
from photoservo.vision.rig import Rig

if TYPE_CHECKING:
    from photoservo.vision.fitness import FitnessParams, StereoHue

# columns of `contour_counts`: outer points on a target hue across an edge, on a target hue
# without one, without hue across an edge; and of the kernel's sums besides, for the distinctive
# outline (`outline_spill`): the flat ones whose inner neighbour is on a target hue too (the target
# goes on), and the distinctive weight summed over the other target-hue points not across an edge
TARGET_EDGE, TARGET_FLAT, NO_HUE_EDGE, GOES_ON, RIM_WEIGHT = range(5)
# an outer point and its inner neighbour projected less than this many pixels apart (along rows or
# columns) are not judged: a real edge is blurred over a pixel or two (optics, demosaicing, any
# resampling) and shows only in part between closer pixels, and a fit shrunk to a few pixels read
# every spot of its colour as bounded by edges (on the real pair: at 1-2 px the crate's model at
# 0.6x was "found" on a 12 px red spot, and at half size the front fender's on the rear fender)
MIN_GAP_PX = 3


@dataclass(frozen=True)
class StereoChroma:
    """The pair's chroma planes: (H, W, 2) uint8 a*, b* (OpenCV 8-bit L*a*b*) per camera."""

    left: np.ndarray
    right: np.ndarray


def chroma(bgr: np.ndarray) -> np.ndarray:
    """a*, b* of an 8-bit BGR image: (H, W, 2) uint8, C-contiguous."""
    return np.ascontiguousarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2LAB)[..., 1:])


def stereo_chroma(left_bgr: np.ndarray, right_bgr: np.ndarray) -> StereoChroma:
    """`chroma` of both images of a pair."""
    return StereoChroma(left=chroma(left_bgr), right=chroma(right_bgr))


def outer_neighbours(inner_uv: np.ndarray, outer_uv: np.ndarray) -> np.ndarray:
    """Index (N_out,) int32 of each outer point's nearest inner point (photo px)."""
    if len(outer_uv) == 0 or len(inner_uv) == 0:
        return np.zeros(len(outer_uv), np.int32)
    d2 = ((np.asarray(outer_uv)[:, None, :] - np.asarray(inner_uv)[None, :, :]) ** 2).sum(-1)
    return d2.argmin(axis=1).astype(np.int32)


@njit(cache=True, error_model="numpy", fastmath=_FAST, nogil=True)
def _contour_kernel(R, t, alpha, rig_R, rig_T, cam_l, cam_r, inner_uv, outer_uv, neighbour, target_hues,
                    hue_l, hue_r, ab_l, ab_r, limit2, weight):  # pragma: no cover - compiled
    """(P, 2, 5) sums TARGET_EDGE, TARGET_FLAT, NO_HUE_EDGE, GOES_ON, RIM_WEIGHT per individual
    and camera (module docstring; `contour_cases` reads the same per point); limit2 =
    contour_chroma squared, weight (256,) the distinctive weight of each hue value. Points are
    projected as in fitness_kernel; a pair of points less than MIN_GAP_PX apart is not judged."""
    P = R.shape[0]
    u, v, n_in = _split_points(inner_uv, outer_uv)
    n = u.shape[0]
    out = np.zeros((P, 2, 5), dtype=np.float64)
    a = np.empty((3, 3))
    idx = np.empty(n, np.int32)
    for job in range(2 * P):
        p = job // 2
        c = job % 2
        cam = cam_l if c == 0 else cam_r
        hue = (hue_l if c == 0 else hue_r).ravel()
        ab = (ab_l if c == 0 else ab_r).ravel()
        w = np.int32(cam[4])
        inv_w = 1.0 / cam[4]
        _plane_map(R[p], t[p], alpha[p], rig_R, rig_T, cam, c == 1, a)
        _pixel_indices(a, u, v, cam, idx)
        for k in range(n - n_in):
            io = idx[n_in + k]
            if io < 0:
                continue
            h = hue[io]
            target = h < 180 and target_hues[h]
            ii = idx[neighbour[k]]
            judged = False
            if ii >= 0:
                d = io - ii  # rows and columns apart: d = dr w + dc with |dc| < w / 2 for close points
                dr = np.int32(np.floor(d * inv_w + 0.5))
                dc = d - dr * w
                judged = max(abs(dr), abs(dc)) >= MIN_GAP_PX  # closer: too close for an edge to show
            if not judged:
                if target:
                    out[p, c, 4] += weight[h]
                continue
            da = np.int32(ab[2 * io]) - np.int32(ab[2 * ii])
            db = np.int32(ab[2 * io + 1]) - np.int32(ab[2 * ii + 1])
            edge = da * da + db * db > limit2
            if target:
                if edge:
                    out[p, c, 0] += 1.0
                else:
                    out[p, c, 1] += 1.0
                    hi = hue[ii]
                    if hi < 180 and target_hues[hi]:
                        out[p, c, 3] += 1.0
                    else:
                        out[p, c, 4] += weight[h]
            elif h >= 180 and edge:
                out[p, c, 2] += 1.0
    return out


def _contour_sums(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, model: PhotoModel, frame: StereoHue,
                  chroma: StereoChroma, rig: Rig, params: FitnessParams, weight: np.ndarray | None) -> np.ndarray:
    """The compiled kernel's (P, 2, 5) sums (its docstring); `weight` None: zeros."""
    c = lambda x, dt: np.ascontiguousarray(x, dtype=dt)  # noqa: E731
    inner, neighbour, outer = model.contour_points  # only the inner points that are some outer point's neighbour
    lut = np.zeros(256) if weight is None else c(weight, np.float64)
    return _contour_kernel(c(R, np.float64), c(t, np.float64), c(alpha, np.float64), rig.R, rig.T,
                           camera_vector(rig.left.K, rig.left.dist, rig.left.size),
                           camera_vector(rig.right.K, rig.right.dist, rig.right.size),
                           inner, outer, neighbour, c(model.target_hues, np.bool_),
                           c(frame.left, np.uint8), c(frame.right, np.uint8), chroma.left, chroma.right,
                           float(params.contour_chroma) ** 2, lut)


def contour_counts(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, model: PhotoModel, frame: StereoHue,
                   rig: Rig, params: FitnessParams) -> np.ndarray:
    """(P, 2, 3) counts of the contour rule (module docstring) of poses R (P,3,3), t (P,3) mm,
    alpha (P,) px/mm (model in the left camera frame); `frame.chroma` must be set."""
    return _contour_sums(R, t, alpha, model, frame, frame.chroma, rig, params, None)[..., :3].astype(np.int64)


def outline_spill(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, model: PhotoModel, frame: StereoHue,
                  chroma: StereoChroma, rig: Rig, params: FitnessParams, weight: np.ndarray) -> np.ndarray:
    """(P, 2) the distinctive outline's spill (vision/detection.py) per pose and camera: the outer
    points on a target hue whose inner neighbour is on a target hue too, with no colour edge between
    (judged), count 1; those across an edge 0; the others their hue's `weight` ((256,) lookup,
    `silhouette.distinctive_weight`). Poses as in `contour_counts`; `chroma` the pair's planes."""
    s = _contour_sums(R, t, alpha, model, frame, chroma, rig, params, weight)
    return s[..., GOES_ON] + s[..., RIM_WEIGHT]


def contour_cases(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, model: PhotoModel, frame: StereoHue,
                  chroma: StereoChroma, rig: Rig, params: FitnessParams
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The contour rule's reading of every outer point (module docstring) at poses R (P,3,3), t
    (P,3) mm, alpha (P,) px/mm, in numpy on `fitness.project_uv`: (P, 2, N_out) arrays, axis 1
    the left and right camera — the image hue under the outer point and under its inner
    neighbour (NO_HUE where none or outside the image), whether the pair is judged (both inside,
    at least MIN_GAP_PX apart) and whether a colour edge lies between them (a*b* distance above
    contour_chroma)."""
    from photoservo.vision.fitness import project_uv

    inner_uv, nb, outer_uv = model.contour_points  # only the inner points that are some outer point's neighbour
    inner_l, inner_r = project_uv(R, t, alpha, inner_uv, rig)
    outer_l, outer_r = project_uv(R, t, alpha, outer_uv, rig)
    cams = []
    for hue, ab, inner, outer in ((frame.left, chroma.left, inner_l, outer_l),
                                  (frame.right, chroma.right, inner_r, outer_r)):
        def at(uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            H, W = hue.shape
            with np.errstate(invalid="ignore"):
                q = np.floor(uv + 0.5)
                ok = (q[..., 0] >= 0) & (q[..., 0] < W) & (q[..., 1] >= 0) & (q[..., 1] < H)
            return np.where(ok, q[..., 1], 0).astype(np.intp) * W + np.where(ok, q[..., 0], 0).astype(np.intp), ok
        io, ok_o = at(outer)
        ii, ok_i = at(inner[:, nb])
        W = hue.shape[1]
        dr = np.floor((io - ii) / W + 0.5).astype(np.intp)  # as the kernel: rows apart, then columns
        gap = np.maximum(np.abs(dr), np.abs(io - ii - dr * W)) >= MIN_GAP_PX
        d = ab.reshape(-1, 2)[io].astype(np.int32) - ab.reshape(-1, 2)[ii].astype(np.int32)
        edge = (d ** 2).sum(-1) > float(params.contour_chroma) ** 2
        h = hue.ravel()
        cams.append((np.where(ok_o, h[io], NO_HUE), np.where(ok_i, h[ii], NO_HUE), ok_o & ok_i & gap, edge))
    return tuple(np.stack(x, axis=1) for x in zip(*cams))  # type: ignore[return-value]


def judged_share(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, frame: StereoHue,
                 chroma: StereoChroma, rig: Rig, params: FitnessParams) -> np.ndarray:
    """(2,): per camera, the share of ONE pose's outer points the contour rule judges (both points of
    the pair inside the image and at least MIN_GAP_PX apart: `contour_cases`). A fit a few pixels
    long has none: every outer point on a target hue then costs as under the paper's rule, and no
    outer point can show the outline (vision/detection.py). R (3, 3), t (3,) mm, alpha px/mm."""
    _, _, judged, _ = contour_cases(np.asarray(R)[None], np.asarray(t, float)[None], np.array([float(alpha)]),
                                    model, frame, chroma, rig, params)
    return judged[0].mean(axis=-1) if judged.shape[-1] else np.zeros(2)


def contour_counts_reference(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, model: PhotoModel,
                             frame: StereoHue, rig: Rig, params: FitnessParams) -> np.ndarray:
    """`contour_counts` in numpy (the specification, on `contour_cases`)."""
    h, _, ok, edge = contour_cases(R, t, alpha, model, frame, frame.chroma, rig, params)
    target = target_hue_lut(model.target_hues)[h]
    return np.stack([(ok & target & edge).sum(-1), (ok & target & ~edge).sum(-1),
                     (ok & (h >= HUE_BINS) & edge).sum(-1)], axis=-1).astype(np.int64)


def outline_spill_reference(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, model: PhotoModel,
                            frame: StereoHue, chroma: StereoChroma, rig: Rig, params: FitnessParams,
                            weight: np.ndarray) -> np.ndarray:
    """`outline_spill` in numpy (the specification, on `contour_cases`)."""
    h, h_in, judged, edge = contour_cases(R, t, alpha, model, frame, chroma, rig, params)
    lut = target_hue_lut(model.target_hues)
    target = lut[h]
    goes_on = target & judged & ~edge & lut[h_in]
    rim = target & ~(judged & edge) & ~goes_on
    return goes_on.sum(axis=-1) + (np.asarray(weight, np.float64)[h] * rim).sum(axis=-1)


def with_contour(counts: np.ndarray, contour: np.ndarray, params: FitnessParams) -> np.ndarray:
    """The fitness' case counts (P, 2, N_COUNTS) with the contour rule applied (module
    docstring), as float64 (a flat outer point counts w_outer_match / w_outer_mismatch times)."""
    from photoservo.vision.fitness import OUT_MATCH, OUT_MISMATCH

    out = counts.astype(np.float64)
    te, tf, ne = (contour[..., k].astype(np.float64) for k in (TARGET_EDGE, TARGET_FLAT, NO_HUE_EDGE))
    extra = params.w_outer_match / params.w_outer_mismatch - 1.0 if params.w_outer_mismatch > 0 else 0.0
    out[..., OUT_MATCH] += te + ne
    out[..., OUT_MISMATCH] += -te + max(extra, 0.0) * tf
    return out
