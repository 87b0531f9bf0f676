"""Stereo fitness of the photo-model (method step 3) — the hot path of the estimator.

A candidate is a pose of the model in the LEFT camera frame and the photo's scale alpha:

    X_left  = R · X_model + t,        X_model = (u/alpha, v/alpha, 0)  mm   (method step 2)
    X_right = R_s · X_left + T_s                                           (rig [stereo])

Every inner point S_in and outer point S_out of the photo-model is projected into both images
with the rig's pinhole + OpenCV distortion model (== `cv2.projectPoints`), rounded to the
nearest pixel, and the hue h there is read from the frame's hue image.

Per camera c in {L, R} (method step 3, the "textbook" form):

    s_in(i)  = +w_in_match      if h != NO_HUE and d(h, hue_i) <= tol
               -w_in_mismatch   if h != NO_HUE and d(h, hue_i) >  tol
               0                if h == NO_HUE                    (glare, foam, shadow)
               -w_outside       if the point falls outside the image or behind the camera
    s_out(j) = +w_out_match     if h != NO_HUE and h is not a target hue
               -w_out_mismatch  if h != NO_HUE and h is a target hue (model.target_hues)
               0                if h == NO_HUE
               -w_outside       if outside / behind

    F_c = ( sum_i s_in(i) + sum_j s_out(j) ) / ( w_in_match·N_in + w_out_match·N_out )

d is the circular hue distance (0..90 OpenCV steps). The denominator is fixed, so a perfect
match scores exactly 1.0 and a pixel without hue neither rewards nor punishes (it contributes 0,
and it cannot raise the score by shrinking the denominator). The two cameras combine as
(`[fitness] combine`):

    mean:     F = (F_L + F_R) / 2                    (the paper's form, default)
    min:      F = min(F_L, F_R)                      (demand both cameras)
    product:  F = max(F_L, 0) · max(F_R, 0)          (demand both; 1.0 still means perfect)

Where the target's hues cover most of the pair (the estimator's `hues_everywhere`), outer points on
a target hue say nothing of where the target ends; the frame then carries the pair's chroma and
the counts follow the contour rule of `vision/contour.py` (an outer point on a target hue is
judged by the colour edge between it and its nearest inner point).

Two implementations share one API: `fitness_reference` (vectorised numpy, built on
`rig.project_points`, the specification) and the compiled numba kernel of `fitness_kernel`
used by `fitness` when `[fitness] kernel = "numba"` (one thread, default) or
"numba-parallel". Both count, per individual and camera, how many points fell in each case
(`counts_reference` / `counts_compiled`, equal in the tests); F follows from the counts by the
formula above (`_combine`, and `fitness_kernel.combine` for the kernel).

Speed (benchmarks/fitness_speed.py): one generation of 30 individuals x 1000 points takes
~0.3 ms with the kernel against ~10-30 ms for the numpy reference and 213 ms in the paper.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from photoservo.errors import InputError
from photoservo.vision.photo_model import (
    HUE_BINS,
    NO_HUE,
    PhotoModel,
    hue_and_saturation,
    hue_distance,
    hue_image,
)
from photoservo.vision.rig import Rig, project_points

if TYPE_CHECKING:
    from photoservo.vision.contour import StereoChroma

# Columns of the per-camera count array (P, 2, N_COUNTS).
IN_MATCH, IN_MISMATCH, OUT_MATCH, OUT_MISMATCH, OUTSIDE = range(5)
N_COUNTS = 5


@dataclass(frozen=True)
class FitnessParams:
    """[fitness] config: weights and tolerances of the stereo fitness (method step 3)."""

    hue_tolerance: int  # an inner point agrees when the circular hue distance is <= this (0..90)
    min_saturation: int  # 0..255: image pixels greyer than this carry no hue
    min_value: int  # 0..255: image pixels darker than this carry no hue
    w_inner_match: float  # reward per inner point on its own hue
    w_inner_mismatch: float  # cost per inner point on another hue
    w_outer_match: float  # reward per outer point on a hue that is not the target's
    w_outer_mismatch: float  # cost per outer point on a target hue
    w_outside: float  # cost per point projected outside the image or behind the camera
    combine: Literal["mean", "min", "product"]  # how left and right scores combine
    contour_chroma: float  # a*b* distance that makes a colour edge for the contour rule (vision/contour.py)
    kernel: Literal["numba", "numba-parallel", "numpy"]  # compiled (1 thread / threads) or reference

    def validate(self, where: str) -> None:
        def key(n: str) -> str:
            return f"{where}.{n}" if where else n

        if not 0 <= self.hue_tolerance <= 90:
            raise InputError(f"config key '{key('hue_tolerance')}': must be 0..90, got {self.hue_tolerance}")
        for n in ("min_saturation", "min_value"):
            v = getattr(self, n)
            if not 0 <= v <= 255:
                raise InputError(f"config key '{key(n)}': must be 0..255, got {v}")
        for n in ("w_inner_match", "w_inner_mismatch", "w_outer_match", "w_outer_mismatch", "w_outside",
                  "contour_chroma"):
            v = getattr(self, n)
            if not (np.isfinite(v) and v >= 0):
                raise InputError(f"config key '{key(n)}': must be a finite number >= 0, got {v}")
        if self.w_inner_match + self.w_outer_match <= 0:
            raise InputError(
                f"config key '{key('w_inner_match')}': w_inner_match + w_outer_match must be > 0"
            )


@dataclass(frozen=True)
class StereoHue:
    """One stereo frame as hue images (OpenCV hue 0..179, NO_HUE = 255 where a pixel is too grey
    or too dark to carry hue). `left`, `right`: (H, W) uint8, C-contiguous. `chroma`: the pair's
    a*b* planes where the contour rule applies (`vision/contour.py`), else None. `saturation`: the
    pair's HSV saturation (left, right) (H, W) uint8, from the same conversion as the hue, where
    `stereo_hue` was asked for it (`estimate`: detection's `bare_parts.body_purity` reads it), else None."""

    left: np.ndarray
    right: np.ndarray
    chroma: StereoChroma | None = None
    saturation: tuple[np.ndarray, np.ndarray] | None = None


def stereo_hue(left_bgr: np.ndarray, right_bgr: np.ndarray, params: FitnessParams,
               saturation: bool = False) -> StereoHue:
    """Hue images of a stereo pair (BGR uint8) for `fitness`, with the [fitness] saturation and
    value floors (glare, foam and shadow get NO_HUE); with `saturation`, the pair's saturation too
    (`StereoHue.saturation`; the tracker's frames go without: no plane more per frame)."""
    if saturation:
        (hl, sl), (hr, sr) = (hue_and_saturation(img, params.min_saturation, params.min_value)
                              for img in (left_bgr, right_bgr))
        return StereoHue(left=np.ascontiguousarray(hl), right=np.ascontiguousarray(hr), saturation=(sl, sr))

    def one(img: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(hue_image(img, params.min_saturation, params.min_value))

    return StereoHue(left=one(left_bgr), right=one(right_bgr))


@dataclass(frozen=True)
class ModelProjection:
    """Pixel coordinates of the model's sampling points, (P, N, 2) each; NaN behind a camera."""

    inner_left: np.ndarray
    outer_left: np.ndarray
    inner_right: np.ndarray
    outer_right: np.ndarray


def _poses(R: np.ndarray, t: np.ndarray, alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Population arrays as float64 (P,3,3), (P,3), (P,); a single pose is promoted to P = 1."""
    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    alpha = np.asarray(alpha, dtype=np.float64)
    if R.ndim == 2:
        R, t, alpha = R[None], t[None], alpha.reshape(1)
    P = R.shape[0]
    if R.shape != (P, 3, 3) or t.shape != (P, 3) or alpha.shape != (P,):
        raise ValueError(f"population shapes must be R (P,3,3), t (P,3), alpha (P,); got "
                         f"{R.shape}, {t.shape}, {alpha.shape}")
    if not (np.isfinite(R).all() and np.isfinite(t).all() and np.isfinite(alpha).all()
            and (alpha > 0).all()):
        raise ValueError("population has a non-finite pose or an alpha <= 0")
    return R, t, alpha


def _model_points_left(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """X_left = R · (u/alpha, v/alpha, 0) + t for every individual: (P, N, 3) mm."""
    # (uv / alpha) @ R[:, :, :2]^T, (P, N, 3); a batched matmul (BLAS), not einsum (15x slower here)
    scaled = uv[None, :, :] / alpha[:, None, None]  # (P, N, 2)
    return scaled @ R[:, :, :2].transpose(0, 2, 1) + t[:, None, :]


def project_uv(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, uv: np.ndarray,
               rig: Rig) -> tuple[np.ndarray, np.ndarray]:
    """Project photo-model points uv (N, 2) photo px at poses (R, t, alpha) into both cameras of
    `rig` (method step 2): ((P, N, 2) left, (P, N, 2) right) px, NaN behind a camera. R
    (P,3,3) or (3,3), t mm, alpha px/mm."""
    R, t, alpha = _poses(R, t, alpha)
    XL = _model_points_left(R, t, alpha, np.asarray(uv, dtype=np.float64).reshape(-1, 2))
    XR = XL @ rig.R.T + rig.T
    with np.errstate(over="ignore", invalid="ignore"):  # far off-axis points: inf/NaN = outside
        return project_points(XL, rig.left), project_points(XR, rig.right)


def project_model(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, model: PhotoModel, rig: Rig) -> ModelProjection:
    """Project the inner and outer sampling points of `model` at poses (R, t, alpha) into both
    cameras of `rig` (method steps 2-3). R (P,3,3) or (3,3), t mm, alpha px/mm."""
    (il, ir), (ol, orr) = (project_uv(R, t, alpha, uv, rig) for uv in (model.inner_uv, model.outer_uv))
    return ModelProjection(inner_left=il, outer_left=ol, inner_right=ir, outer_right=orr)


def projected(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, rig: Rig,
              proj: ModelProjection | None) -> ModelProjection:
    """The `project_model` of ONE pose (R (3, 3) the model's linear map, `Candidate.R_model`; t (3,) mm in
    the left camera frame; alpha px/mm): `proj` when the caller has it (`detect` projects a candidate once
    for all of its rules), else computed."""
    return project_model(R, t, alpha, model, rig) if proj is None else proj


def nearest_pixel(uv: np.ndarray, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The nearest pixel to (..., 2) pixel coordinates in an image of `shape` (H, W, ...), as the
    fitness reads it: (row, column, inside), rows and columns (...) intp, 0 where the point falls
    outside the image or is not finite (inside False). Pixel centres are at integer coordinates
    (OpenCV): pixel k covers [k - 0.5, k + 0.5)."""
    Hh, Ww = shape[:2]
    with np.errstate(invalid="ignore"):
        c = np.floor(uv + 0.5)
        inside = (c[..., 0] >= 0) & (c[..., 0] < Ww) & (c[..., 1] >= 0) & (c[..., 1] < Hh)
    ci = np.where(inside, c[..., 0], 0).astype(np.intp)
    ri = np.where(inside, c[..., 1], 0).astype(np.intp)
    return ri, ci, inside


def _sample(uv: np.ndarray, hue: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest-pixel hue at (P, N, 2) pixel coordinates: (hue (P,N) int, inside (P,N) bool)
    (`nearest_pixel`)."""
    ri, ci, inside = nearest_pixel(uv, hue.shape)
    return hue[ri, ci].astype(np.int16), inside


def inner_hues(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, frame: StereoHue,
               rig: Rig, proj: ModelProjection | None = None) -> np.ndarray:
    """The image hue under each inner point S_in of ONE pose, as the fitness reads it (nearest
    pixel): (2, N_in) int16, rows left and right camera, NO_HUE where the pixel carries no hue or
    the point falls outside the image. R (3, 3) the model's linear map, t (3,) mm in the left
    camera frame, alpha px/mm; `proj`: that pose's `project_model` (computed when None)."""
    p = projected(R, t, alpha, model, rig, proj)
    rows = []
    for uv, hue in ((p.inner_left, frame.left), (p.inner_right, frame.right)):
        h, inside = _sample(uv, hue)
        rows.append(np.where(inside[0], h[0], NO_HUE))
    return np.stack(rows).astype(np.int16)


def _count_camera(uv_in: np.ndarray, uv_out: np.ndarray, hue: np.ndarray, model: PhotoModel,
                  params: FitnessParams) -> np.ndarray:
    """Case counts (P, N_COUNTS) of one camera — the per-point cases of the module docstring."""
    h_in, ok_in = _sample(uv_in, hue)
    h_out, ok_out = _sample(uv_out, hue)
    has_in = ok_in & (h_in < HUE_BINS)
    has_out = ok_out & (h_out < HUE_BINS)
    agree = hue_distance(h_in, model.inner_hue[None, :]) <= params.hue_tolerance
    is_target = np.asarray(model.target_hues, dtype=bool)[np.where(has_out, h_out, 0)]
    counts = np.empty((uv_in.shape[0], N_COUNTS), dtype=np.int64)
    counts[:, IN_MATCH] = (has_in & agree).sum(axis=1)
    counts[:, IN_MISMATCH] = (has_in & ~agree).sum(axis=1)
    counts[:, OUT_MATCH] = (has_out & ~is_target).sum(axis=1)
    counts[:, OUT_MISMATCH] = (has_out & is_target).sum(axis=1)
    counts[:, OUTSIDE] = (~ok_in).sum(axis=1) + (~ok_out).sum(axis=1)
    return counts


def counts_reference(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, model: PhotoModel,
                     frame: StereoHue, rig: Rig, params: FitnessParams) -> np.ndarray:
    """Per-individual, per-camera case counts (P, 2, N_COUNTS), numpy reference."""
    p = project_model(R, t, alpha, model, rig)
    left = _count_camera(p.inner_left, p.outer_left, frame.left, model, params)
    right = _count_camera(p.inner_right, p.outer_right, frame.right, model, params)
    return np.stack([left, right], axis=1)


def _combine(counts: np.ndarray, n_in: int, n_out: int, params: FitnessParams) -> np.ndarray:
    """Counts (P, 2, N_COUNTS) -> fitness (P,): F_c per camera, then the [fitness] combine."""
    c = counts.astype(np.float64)
    num = (params.w_inner_match * c[..., IN_MATCH] - params.w_inner_mismatch * c[..., IN_MISMATCH]
           + params.w_outer_match * c[..., OUT_MATCH] - params.w_outer_mismatch * c[..., OUT_MISMATCH]
           - params.w_outside * c[..., OUTSIDE])
    den = params.w_inner_match * n_in + params.w_outer_match * n_out
    F = num / den if den > 0 else np.zeros_like(num)
    if params.combine == "mean":
        return 0.5 * (F[:, 0] + F[:, 1])
    if params.combine == "min":
        return np.minimum(F[:, 0], F[:, 1])
    return np.maximum(F[:, 0], 0.0) * np.maximum(F[:, 1], 0.0)


def point_weight(model: PhotoModel, params: FitnessParams) -> float:
    """The fitness' resolution (method step 3): what one inner point turning from no hue to a match
    in both cameras adds to F, w_inner_match / (w_inner_match·N_in + w_outer_match·N_out) with the
    cameras combined by their mean. Two poses that differ by less score alike to within the
    projection's rounding to pixels."""
    den = params.w_inner_match * len(model.inner_uv) + params.w_outer_match * len(model.outer_uv)
    return params.w_inner_match / den if den > 0 else 0.0


def fitness_reference(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, model: PhotoModel,
                      frame: StereoHue, rig: Rig, params: FitnessParams) -> np.ndarray:
    """Stereo fitness (P,) of a population, numpy reference of method step 3 (module docstring)."""
    counts = counts_reference(R, t, alpha, model, frame, rig, params)
    if frame.chroma is not None:
        from photoservo.vision.contour import contour_counts_reference, with_contour

        counts = with_contour(counts, contour_counts_reference(R, t, alpha, model, frame, rig, params), params)
    return _combine(counts, len(model.inner_uv), len(model.outer_uv), params)


def fitness(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, model: PhotoModel, frame: StereoHue,
            rig: Rig, params: FitnessParams) -> np.ndarray:
    """Stereo fitness (P,) of a whole population (method step 3; formula in the module docstring).

    R: (P, 3, 3) rotations and t: (P, 3) mm, model in the left camera frame
    (X_left = R · X_model + t); alpha: (P,) px/mm. A single pose ((3,3), (3,), scalar) gives (1,).
    1.0 is a perfect match in both cameras; 0 is "nothing seen". A non-finite pose or an
    alpha <= 0 is a programming error (ValueError).
    """
    if params.kernel == "numpy":
        return fitness_reference(R, t, alpha, model, frame, rig, params)
    from photoservo.vision import fitness_kernel as fk

    counts = counts_compiled(R, t, alpha, model, frame, rig, params)
    if frame.chroma is not None:
        from photoservo.vision.contour import contour_counts, with_contour

        R, t, alpha = _poses(R, t, alpha)
        counts = with_contour(counts, contour_counts(R, t, alpha, model, frame, rig, params), params)
    # float64 counts either way: one compiled signature of `combine` (the contour rule's are fractional)
    counts = np.asarray(counts, dtype=np.float64)
    w = np.array([params.w_inner_match, params.w_inner_mismatch, params.w_outer_match,
                  params.w_outer_mismatch, params.w_outside])
    mode = ("mean", "min", "product").index(params.combine)
    return fk.combine(counts, len(model.inner_uv), len(model.outer_uv), w, mode)


def counts_compiled(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, model: PhotoModel,
                    frame: StereoHue, rig: Rig, params: FitnessParams) -> np.ndarray:
    """Per-individual, per-camera case counts (P, 2, N_COUNTS) by the numba kernel
    (`fitness_kernel`); equal to `counts_reference`."""
    from photoservo.vision import fitness_kernel as fk

    R, t, alpha = _poses(R, t, alpha)
    kernel = fk.counts_parallel if params.kernel == "numba-parallel" else fk.counts_serial
    return kernel(
        R, t, alpha, rig.R, rig.T,
        fk.camera_vector(rig.left.K, rig.left.dist, rig.left.size),
        fk.camera_vector(rig.right.K, rig.right.dist, rig.right.size),
        _c(model.inner_uv, np.float64), _c(model.inner_hue, np.uint8),
        _c(model.outer_uv, np.float64), _c(model.target_hues, np.bool_),
        _c(frame.left, np.uint8), _c(frame.right, np.uint8),
        params.hue_tolerance,
    )


def _c(a: np.ndarray, dtype: type) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=dtype)
