"""The appearance cue: the brightness layout inside the creature, compared with the photo's by a
correlation that normalises itself on the image.

The fitness (method step 3) compares each inner point's hue with the image's. A creature of one
hue turned head to tail about its middle covers nearly the same pixels with the same hue, so the
hue fitness scores the two poses alike (squid and crab twins, README "Accuracy"). The photo's
brightness is not symmetric: the mantle, the head, the eyes, the shading of the legs. Per inner
point S_in the photo-model keeps the photo's grey level (`PhotoModel.inner_value`, sampled from
the photo blurred over half a sampling pitch); at a pose, the inner points are projected into
each camera, the grey image is sampled there (blurred over the same half pitch as it appears in
that image). Over the inner points that land on one of the target's hues (nearest pixel, as the
fitness reads it: foam, glare and water beside the creature carry no part of its layout, and a
white foam band would otherwise dominate), each set of samples loses its least-squares plane
over the points' model offsets (u, v) — a brightness gradient across the creature is the light's
(the sun on a curved body, a studio lamp in the photo), not the creature's: on the harbour
generator the scene's and the photo's gradients often run opposite and the plain correlation
then prefers the turned twin — and the residuals are correlated (Pearson, per camera):

    g~ = g - plane_fit(g; u, v),   p~ = p - plane_fit(p; u, v)
    rho_c = sum_i g~_i p~_i / sqrt(sum_i g~_i^2 · sum_i p~_i^2)
    A     = mean over the cameras with >= MIN_POINTS inner points on target hue of rho_c   (-1..1)

rho is invariant to a gain and an offset of the image's grey (a brighter, darker or evenly
colour-cast copy of a creature of one hue scores the same), and a pose turned by 180 degrees
about the creature's middle pairs each photo sample with the grey of the other end: it scores
lower wherever the creature's brightness is not symmetric. It is not a detector: the samples of
water under a look-alike correlate with nothing, but neither does a creature under foam. Use it
to choose between poses the hue fitness cannot tell apart (`estimator`'s twin decision).

`body_layout` is the same correlation for detection (`vision/detection.py`): is there a
creature's brightness layout under a candidate at all? It reads the brightness V = max(B, G, R)
(`brightness`: the pattern of a saturated creature lies in its strongest channel; the photo's
`PhotoModel.inner_brightness`) at the inner points at least `BODY_MARGIN_PX` image px inside the
photo's outline (`body_points`) — whatever hue the image has there, so that a model laid on water
or on a float of the creature's colour is read where its body falls — and takes the worse camera.

Frames: R, t model in the left camera frame (mm); alpha px/mm; images (H, W) float32 grey
(`sampling.grey`) or brightness (`sampling.brightness`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from photoservo.vision.fitness import StereoHue, nearest_pixel
from photoservo.vision.photo_model import PhotoModel, target_hue_lut
from photoservo.vision.rig import Rig, project_points
from photoservo.vision.sampling import brightness, grey, image_values, sampling_pitch, saturation

MIN_POINTS = 8  # a camera whose image holds fewer inner points on target hue gives no correlation
BODY_MARGIN_PX = 1.5  # body_points: inner points at least this far (image px) inside the photo's outline


@dataclass(frozen=True)
class StereoGrey:
    """One stereo frame as grey images (float32 (H, W), `sampling.grey`)."""

    left: np.ndarray
    right: np.ndarray


def stereo_grey(left_bgr: np.ndarray, right_bgr: np.ndarray) -> StereoGrey:
    """Grey images of a stereo pair (BGR uint8) for `appearance`."""
    return StereoGrey(left=grey(left_bgr), right=grey(right_bgr))


def stereo_value(left_bgr: np.ndarray, right_bgr: np.ndarray) -> StereoGrey:
    """Brightness images (`brightness`) of a stereo pair (BGR uint8) for `body_layout`."""
    return StereoGrey(left=brightness(left_bgr), right=brightness(right_bgr))


def stereo_saturation(left_bgr: np.ndarray, right_bgr: np.ndarray,
                      planes: tuple[np.ndarray, np.ndarray] | None = None) -> StereoGrey:
    """Saturation images (`sampling.saturation`) of a stereo pair (BGR uint8) for `bare_parts.body_purity`;
    from `planes`, the pair's uint8 saturation where its hue was computed with it (`StereoHue.saturation`)."""
    if planes is not None:
        return StereoGrey(left=planes[0].astype(np.float32), right=planes[1].astype(np.float32))
    return StereoGrey(left=saturation(left_bgr), right=saturation(right_bgr))


def detrended(values: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """values (N,) less their least-squares plane over the model's point offsets uv (N, 2):
    the layout without a brightness gradient across the creature (the light's, not its own)."""
    A = np.column_stack([np.ones(len(uv)), uv])
    coef, *_ = np.linalg.lstsq(A, values, rcond=None)
    return values - A @ coef


def correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson correlation of two sample vectors (nan when either is constant or empty)."""
    a = np.asarray(a, dtype=np.float64) - np.mean(a)
    b = np.asarray(b, dtype=np.float64) - np.mean(b)
    den = math.sqrt(float(a @ a) * float(b @ b))
    return float(a @ b) / den if den > 1e-9 else math.nan


def on_target(uv: np.ndarray, hue: np.ndarray, target_hues: np.ndarray) -> np.ndarray:
    """Image points uv (N, 2) px whose nearest pixel carries one of the target's hues (bool (N,);
    False outside the image or on a pixel without hue)."""
    ri, ci, inside = nearest_pixel(uv, hue.shape)
    h = hue[ri, ci]
    return inside & target_hue_lut(target_hues)[h]


def camera_correlations(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, samples: np.ndarray,
                        planes: StereoGrey, rig: Rig, select) -> list[float]:
    """rho_c of each camera (left, right; module docstring): the image `planes` sampled at the
    projected inner points (blurred over half a sampling pitch as it appears there), correlated
    with the photo's `samples` (N_in,), both detrended, over the points `select(k, uv)` keeps
    (k = 0 left, 1 right; uv (N_in, 2) image px); nan for a camera with fewer than MIN_POINTS. R (3, 3)
    the model's linear map, t (3,) mm, alpha px/mm."""
    R = np.asarray(R, dtype=np.float64).reshape(3, 3)
    t = np.asarray(t, dtype=np.float64).reshape(3)
    X = np.column_stack([model.inner_uv / alpha, np.zeros(len(model.inner_uv))]) @ R.T + t
    half_pitch = 0.5 * sampling_pitch(model.inner_uv)
    rhos = []
    for k, (cam, Xc, img) in enumerate(((rig.left, X, planes.left), (rig.right, X @ rig.R.T + rig.T, planes.right))):
        zc = float(np.median(Xc[:, 2]))
        if zc <= 0:
            rhos.append(math.nan)
            continue
        # half a pitch as it appears in this camera: photo px -> mm (1/alpha) -> image px (f / z)
        sigma = half_pitch * float(cam.K[0, 0]) / (alpha * zc)
        uv = project_points(Xc, cam)
        vals, ok = image_values(uv, img, sigma)
        ok &= select(k, uv)
        r = math.nan
        if ok.sum() >= MIN_POINTS:
            uv_ok = model.inner_uv[ok]
            r = correlation(detrended(vals[ok], uv_ok), detrended(np.asarray(samples, np.float64)[ok], uv_ok))
        rhos.append(r)
    return rhos


def appearance(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, frame: StereoHue,
               grey_frame: StereoGrey, rig: Rig) -> float:
    """The appearance score A of one pose (module docstring): the mean over both cameras of the
    correlation between the photo's grey at the inner points (`model.inner_value`) and the
    image's grey at their projections, over the points that land on a target hue, each less its
    plane over the points' model offsets (`detrended`). R (3, 3) the
    model's linear map (a rotation, or `Candidate.R_model` with the per-axis size), t (3,) mm,
    alpha px/mm; `frame` the pair's hue images, `grey_frame` its grey images. nan when the model
    has no grey samples or no camera has MIN_POINTS inner points on target hue."""
    if len(model.inner_value) != len(model.inner_uv):
        return math.nan
    hues = (frame.left, frame.right)
    rhos = [r for r in camera_correlations(R, t, alpha, model, model.inner_value, grey_frame, rig,
                                           lambda k, uv: on_target(uv, hues[k], model.target_hues))
            if np.isfinite(r)]
    return float(np.mean(rhos)) if rhos else math.nan


def body_points(model: PhotoModel, scale: float) -> np.ndarray:
    """(N_in,) bool: the inner points at least BODY_MARGIN_PX image px inside the photo mask's
    outline at apparent scale `scale` (image px per photo px), whose image samples do not mix
    with what lies beside the creature."""
    depth = cv2.distanceTransform((model.mask > 0).astype(np.uint8), cv2.DIST_L2, 5)
    c = np.clip(np.round(model.inner_uv + np.asarray(model.origin_px)).astype(np.intp), 0,
                [depth.shape[1] - 1, depth.shape[0] - 1])
    return depth[c[:, 1], c[:, 0]] >= BODY_MARGIN_PX / max(scale, 1e-9)


def body_layout(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, value_frame: StereoGrey, rig: Rig,
                body: np.ndarray) -> float:
    """The body-brightness layout B of one pose (module docstring): the worse camera's correlation
    between the photo's brightness (`model.inner_brightness`) and the image's (`value_frame`,
    `stereo_value`) over the inner points `body` (`body_points`), detrended. Arguments as
    `appearance`. nan when the model has no brightness samples or a camera has too few points."""
    if len(model.inner_brightness) != len(model.inner_uv):
        return math.nan
    rhos = camera_correlations(R, t, alpha, model, model.inner_brightness, value_frame, rig, lambda k, uv: body)
    return float(min(rhos)) if all(np.isfinite(rhos)) else math.nan
