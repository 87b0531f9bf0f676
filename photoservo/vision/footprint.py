"""Does the blob of the target's hues under a candidate end where its model does? Detection's
comparison of a candidate with what lies under it, in each image of the pair.

A creature under its photo-model fills the model's footprint and ends at its outline (within a
blur's width; another individual's limbs differ by a little more). A model fitted onto part of
something larger of the target's colour does not: a fish's model on a squid's mantle, the
squid's head and arms going on past the fish's snout (harbour null 2001), a squid's model
inside a crab (renderer null 2023). The outline test sees such a spill only at the one band of
outer points S_out, and lets it through where the appearance cues excuse it (2001: outline half on
the squid, grey and body correlations 0.26 and 0.34, just above `min_appearance`) or where the
pair's own null spills as much (2023: the crab fills much of the image, so the null placements land
on it too; its blob goes on by 0.12 only, the crab's legs inside the squid model's rim: not
separable from a creature with debris touching it, 0.09, by this cue).

Here the image itself is asked: the target-hue pixels (the model's `target_hues`) of each image,
split into 8-connected blobs; the blobs the model's footprint F lies on (at least
`BLOB_MIN_SHARE` of F's area, and 3 px, inside F) are the thing under the candidate, B; its part
beyond F dilated by a rim of `BLOB_RIM_FRAC` of F's linear size (blur; another individual's
outline) is what goes on past the model:

    beyond_c = |B \\ dilate(F, r)| / |F|,   r = max(RIM_MIN_PX, BLOB_RIM_FRAC sqrt|F|)   (camera c)

F is the photo-model's filled outline (the photo mask's outer contours) projected at the pose.
Detection (vision/detection.py) reads the smaller of the two cameras' (both must see the blob go
on: one camera alone sees up to 5 times the footprint beside a true creature, harbour 1038 and
1120 at the truth) where hue bounds the target (`frame.chroma` None; where the contour rule bounds
it the water carries the target's hues and blobs merge with it), and only to decide whether an
outline that spills may be excused by the appearance cues: a creature with a look-alike of its
hues touching it goes on past its model too (renderer 1431 at the truth: 0.43), but its outline
is clean. Scale-free: a share of the footprint's own area, at the candidate's own scale.

Frames: poses as in `fitness` (R the model's linear map, t mm in the left camera frame, alpha
px/mm); the hue images of the pair (`StereoHue`).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from photoservo.vision.fitness import StereoHue, project_uv
from photoservo.vision.photo_model import PhotoModel, target_hue_lut
from photoservo.vision.rig import Rig

BLOB_MIN_SHARE = 0.02  # a blob is under the candidate when this share of the footprint's area lies on it
BLOB_RIM_FRAC = 0.05  # the rim around the footprint a blob may pass it by: this share of sqrt(area)...
RIM_MIN_PX = 2  # ...and at least this (px): the images' blur


def outline_uv(model: PhotoModel) -> list[np.ndarray]:
    """The photo mask's outer contours as model offsets (photo px from the model origin): a list of
    (K, 2) float64 polygons."""
    contours, _ = cv2.findContours((np.asarray(model.mask) > 0).astype(np.uint8), cv2.RETR_EXTERNAL,
                                   cv2.CHAIN_APPROX_SIMPLE)
    origin = np.asarray(model.origin_px, np.float64)
    return [c[:, 0, :].astype(np.float64) - origin for c in contours if len(c) >= 3]


def footprints(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, rig: Rig,
               shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """The model's filled outline at ONE pose in the left and the right image ((H, W) bool each;
    parts outside an image are cut off)."""
    out = []
    polys = outline_uv(model)
    projected = [project_uv(R, t, alpha, uv, rig) for uv in polys]
    for k in range(2):
        F = np.zeros(shape, np.uint8)
        pts = [np.round(p[k][0]).astype(np.int32) for p in projected if np.isfinite(p[k][0]).all()]
        if pts:
            cv2.fillPoly(F, pts, 1)
        out.append(F.astype(bool))
    return out[0], out[1]


def blob_beyond(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, frame: StereoHue,
                rig: Rig) -> np.ndarray:
    """(2,) per camera (left, right): the share `beyond_c` (module docstring) of the footprint's
    area by which the blobs of target hue under ONE pose go on past its outline; nan where the
    footprint holds no pixel of the image. Read in a window of the footprint's box widened by its
    longer side on every side (a blob going on further counts as far as that: a share of 8 or more)."""
    lut = target_hue_lut(model.target_hues).astype(np.uint8)  # NO_HUE and above: not a target hue
    out = np.full(2, math.nan)
    for k, (F, hue) in enumerate(zip(footprints(R, t, alpha, model, rig, frame.left.shape), (frame.left, frame.right))):
        rows, cols = np.any(F, axis=1), np.any(F, axis=0)
        if not rows.any():
            continue
        r0, r1 = np.flatnonzero(rows)[[0, -1]]
        c0, c1 = np.flatnonzero(cols)[[0, -1]]
        m = int(max(r1 - r0, c1 - c0)) + 1
        win = (slice(max(0, r0 - m), r1 + m + 1), slice(max(0, c0 - m), c1 + m + 1))
        F = F[win]
        area = int(np.count_nonzero(F))
        T = cv2.LUT(np.ascontiguousarray(hue[win]), lut)
        n, labels = cv2.connectedComponents(T, connectivity=8)
        under = np.bincount(labels[F & (T > 0)], minlength=n)
        under[0] = 0  # label 0: off the target's hues
        B = (under >= max(3.0, BLOB_MIN_SHARE * area))[labels]
        r = max(RIM_MIN_PX, int(round(BLOB_RIM_FRAC * math.sqrt(area))))
        rim = cv2.dilate(F.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1)))
        out[k] = np.count_nonzero(B & (rim == 0)) / area
    return out
