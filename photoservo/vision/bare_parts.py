"""Is an absent part a limb the image does not show at all? The parts check's second look at
what its absent parts land on, against the water around the candidate in the same image.

The parts check (`vision/parts.py`) lets a candidate have a few of its photo-model's parts absent
(`[estimator] max_absent_parts`, 2 of 12): a true creature loses parts there too. What a lost
part lands on differs. A thin limb blurred into the water (a squid's arms at a few pixels across)
leaves pixels between the water's colour and the body's; another individual's limb, lying
elsewhere than the photo's, leaves the photo's limb on water, one part. A look-alike of one hue
under a creature's model — a fishing float or a leaf under a squid's or a crab's model fitted
small onto it (harbour nulls 1567, 1582, 1609, 1663, 1693: contrast 0.62-0.77, outline clean,
2 of 12 parts absent) — leaves the model's thinnest parts, the arms, on bare water: pixels of the
water's own colour, while the float's body holds the rest. (The float is drawn in the photo's
mean hue, and every photo-model those nulls hold lies within one hue tolerance of one hue, so no
hue layout tells the float from the creature.)

Per camera the water's colour is read around the candidate itself — a per-frame null: the colour
c = (grey, a*, b*) of the image at the outer points S_out that land on hue but not on a target hue
(the water beside the model), their median w, and at the inner points on a target hue (the body)
the median b. Every point's position along the line from the water's colour to the body's is

    x = (c - w) · (b - w) / |b - w|^2          (0 the water, 1 the body)

and s the spread (standard deviation) of x over the water's outer points. A part absent in a
camera (the parts check's rule, `parts.absent_flags`) lies on bare water there when its points'
mean x stands less than `z` standard errors above the water's,

    mean x < z · s / sqrt(n),   n its points' distinct pixels,

and on bare water when it does so in both cameras (a camera that sees it present, or cannot judge
— under `MIN_WATER` water points or `MIN_BODY` body points, or a body no more than `MIN_SPAN`
colour units from the water — says it is not bare). Detection (`vision/detection.py`) rejects a
candidate with two or more parts absent of which any lies on bare water: one part on water is
another individual's limb, two absent with a trace of colour a blurred pair of arms, two absent
with one bare a model wider than what lies under it.

Frames: poses as in `fitness` (R the model's linear map, t mm in the left camera frame, alpha
px/mm); images: the pair's hue (`StereoHue`), grey (`appearance.StereoGrey`) and a*b* chroma
(`contour.StereoChroma`). Each rule reads ONE pose's points in both cameras; `proj`, where given, is that
pose's `fitness.project_model` (detection projects a candidate once for all of them), else it is computed.
"""

from __future__ import annotations

import numpy as np

from photoservo.vision.appearance import StereoGrey
from photoservo.vision.contour import StereoChroma
from photoservo.vision.fitness import ModelProjection, StereoHue, nearest_pixel, projected
from photoservo.vision.parts import FOAM, absent_flags, under_foam
from photoservo.vision.photo_model import HUE_BINS, PhotoModel, target_hue_lut
from photoservo.vision.rig import Rig

BARE_Z = 2.0  # standard errors: a part's mean colour position closer to the water's than this is bare water
MIN_WATER = 8  # a camera judges only with at least this many water points (outer points off target hue)...
MIN_BODY = 8  # ...and body points (inner points on target hue)...
MIN_SPAN = 4.0  # ...and a body at least this far from the water in (grey, a*, b*) units
WATER_STRIDE = 7  # `water_chroma` reads every this-th pixel of the water
NEUTRAL_AB = 128  # OpenCV 8-bit L*a*b*: a* = b* = 128 is grey (no chroma)


def _colours(uv: np.ndarray, grey: np.ndarray, ab: np.ndarray, hue: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """At (N, 2) pixel coordinates (nearest pixel, as the fitness reads: `fitness.nearest_pixel`):
    the colour (N, 3) (grey, a*, b*), the hue (N,) (NO_HUE outside the image), inside (N,) bool and
    the flat pixel index (N,) (-1 outside)."""
    W = hue.shape[1]
    ri, ci, inside = nearest_pixel(uv, hue.shape)
    col = np.column_stack([grey[ri, ci], ab[ri, ci, 0], ab[ri, ci, 1]]).astype(np.float64)
    h = np.where(inside, hue[ri, ci], HUE_BINS).astype(np.int16)
    return col, h, inside, np.where(inside, ri * W + ci, -1)


def bare_flags(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, frame: StereoHue,
               grey_frame: StereoGrey, chroma: StereoChroma, rig: Rig, labels: np.ndarray,
               z: float = BARE_Z, foam_share: float = 1.0, proj: ModelProjection | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """One pose's parts (module docstring): (absent (2, n_parts) bool per camera, as the parts
    check counts them, `foam_share` as there (`parts.absent_flags`); bare (n_parts,) bool, absent
    on bare water in both cameras). `labels`:
    `parts.model_parts` of the model."""
    absent, bare = camera_bare_flags(R, t, alpha, model, frame, grey_frame, chroma, rig, labels, z, foam_share, proj)
    return absent, bare[0] & bare[1]


def camera_bare_flags(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, frame: StereoHue,
                      grey_frame: StereoGrey, chroma: StereoChroma, rig: Rig, labels: np.ndarray,
                      z: float = BARE_Z, foam_share: float = 1.0, proj: ModelProjection | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
    """`bare_flags` per camera: (absent (2, n_parts), bare (2, n_parts): absent in that camera and on
    bare water there)."""
    p = projected(R, t, alpha, model, rig, proj)
    n = int(labels.max()) + 1 if len(labels) else 0
    target = target_hue_lut(model.target_hues)
    absent = np.zeros((2, n), bool)
    bare = np.zeros((2, n), bool)
    views = ((p.inner_left[0], p.outer_left[0], frame.left, grey_frame.left, chroma.left),
             (p.inner_right[0], p.outer_right[0], frame.right, grey_frame.right, chroma.right))
    inner = [_colours(uv_in, grey, ab, hue) for uv_in, _, hue, grey, ab in views]
    foam = np.stack([h_in == FOAM for _, h_in, _, _ in inner])  # both cameras' (parts.under_foam)
    if not under_foam(foam, foam_share):
        foam_share = 1.0
    for k, ((_, uv_out, hue, grey, ab), (c_in, h_in, _, pix)) in enumerate(zip(views, inner)):
        c_out, h_out, _, _ = _colours(uv_out, grey, ab, hue)
        hued = h_in < HUE_BINS
        on = target[h_in]
        absent[k] = absent_flags(hued[None], on[None], labels, foam[k][None], foam_share)[0]
        water = (h_out < HUE_BINS) & ~target[h_out]
        if not absent[k].any() or water.sum() < MIN_WATER or on.sum() < MIN_BODY:
            continue
        w = np.median(c_out[water], axis=0)
        axis = np.median(c_in[on], axis=0) - w
        span2 = float(axis @ axis)
        if span2 < MIN_SPAN ** 2:
            continue
        x = (c_in - w) @ axis / span2
        s = max(float(np.std((c_out[water] - w) @ axis / span2)), 1e-6)
        for a in np.flatnonzero(absent[k]):
            m = (labels == a) & (pix >= 0)
            distinct = len(np.unique(pix[m]))
            bare[k, a] = distinct > 0 and float(x[m].mean()) < z * s / np.sqrt(distinct)
    return absent, bare


def bare_counts(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, frame: StereoHue,
                grey_frame: StereoGrey, chroma: StereoChroma, rig: Rig, labels: np.ndarray,
                z: float = BARE_Z, foam_share: float = 1.0, proj: ModelProjection | None = None
                ) -> tuple[int, int, int]:
    """(absent, bare, bare_any): the worse camera's count of absent parts, how many parts lie on bare
    water in both cameras (`bare_flags`), and how many lie on bare water in at least one camera that
    misses them (`camera_bare_flags`): 0 when every absent part leaves a trace of the body's colour
    wherever it is absent."""
    absent, bare = camera_bare_flags(R, t, alpha, model, frame, grey_frame, chroma, rig, labels, z, foam_share, proj)
    return (int(absent.sum(axis=1).max()) if absent.size else 0, int((bare[0] & bare[1]).sum()),
            int((bare[0] | bare[1]).sum()))


def water_chroma(hue: np.ndarray, ab: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(2,) the image's water colour: the median a*, b* over its pixels on hue but off the target's
    hues (`target`, `photo_model.target_hue_lut`; every `WATER_STRIDE`-th such pixel)."""
    water = ~target[hue.ravel()] & (hue.ravel() < HUE_BINS)
    px = ab.reshape(-1, 2)[np.flatnonzero(water)[::WATER_STRIDE]]
    return np.median(px.astype(np.float64), axis=0) if len(px) else np.full(2, np.nan)


def stereo_water(model: PhotoModel, frame: StereoHue, chroma: StereoChroma) -> np.ndarray:
    """(2, 2): `water_chroma` of the left and right image (rows) for `off_water`, read once per pair."""
    target = target_hue_lut(model.target_hues)
    return np.stack([water_chroma(frame.left, chroma.left, target), water_chroma(frame.right, chroma.right, target)])


def body_gap(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, frame: StereoHue,
             chroma: StereoChroma, rig: Rig, proj: ModelProjection | None = None) -> np.ndarray:
    """(2,) per camera, a*b* units (OpenCV 8-bit L*a*b*): how far ONE pose's body stands off the water
    around it — the distance between the median a*b* at its inner points S_in on a target hue (the
    body) and at its outer points S_out on hue off the target's hues (the water beside the model, as
    `bare_flags` reads it); nan in a camera with fewer than `MIN_BODY` body or `MIN_WATER` water
    points, or whose body points carry no chroma at all (a*b* all neutral: the grey planes a compact
    recording replays, `record.planes`, hold no colour to judge by). Hue is the angle of a*b*: near the water's own colour a small shift of it turns the
    angle across the target's hue tolerance, so a body on target hue a few a*b* units off the water
    (harbour held-out 5 null 2266: a dull leaf under a squid's model, 9.8 and 11.4) is a colour the
    water nearly has, not a creature's (tuned harbour answers 23-55)."""
    p = projected(R, t, alpha, model, rig, proj)
    target = target_hue_lut(model.target_hues)
    out = np.full(2, np.nan)
    for k, (uv_in, uv_out, hue, ab) in enumerate(((p.inner_left[0], p.outer_left[0], frame.left, chroma.left),
                                                  (p.inner_right[0], p.outer_right[0], frame.right, chroma.right))):
        ab_in, h_in = _chroma(uv_in, hue, ab)
        ab_out, h_out = _chroma(uv_out, hue, ab)
        body = target[h_in]
        water = (h_out < HUE_BINS) & ~target[h_out]
        # a body on hue with no chroma at all is a pair without colour (a compact recording's grey planes)
        coloured = bool(np.any(ab_in[body] != NEUTRAL_AB))
        if body.sum() >= MIN_BODY and water.sum() >= MIN_WATER and coloured:
            out[k] = float(np.linalg.norm(np.median(ab_in[body], axis=0) - np.median(ab_out[water], axis=0)))
    return out


def body_relief(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, frame: StereoHue,
                value_frame: StereoGrey, rig: Rig, proj: ModelProjection | None = None) -> np.ndarray:
    """(2,) per camera: how much ONE pose's body (inner points on a target hue) varies in brightness
    against the photo at the same points — the coefficient of variation of the image's brightness
    (`value_frame`, `appearance.stereo_value`) over the body points, over that of the photo's
    (`model.inner_brightness`) at those points; nan in a camera with fewer than `MIN_BODY` body points,
    or where either is dark or the photo's does not vary. A ratio of the image with itself and the
    photo with itself (gain-invariant). A leaf or a float of one flat colour under a squid's model
    (harbour held-out 2 null 1861, held-out 5 null 2266: 0.40, 0.46) varies less than half as much
    as the photo's mottled body; a creature, shaded by the light and blurred, 0.88 or more (the tuned
    answers, both generators)."""
    out = np.full(2, np.nan)
    for k, pv, value in _body_samples(R, t, alpha, model, model.inner_brightness, frame, value_frame, rig, proj):
        v = value.astype(np.float64)
        if v.mean() > 0 and pv.mean() > 0 and pv.std() > 0:
            out[k] = float((v.std() / v.mean()) / (pv.std() / pv.mean()))
    return out


def body_purity(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, frame: StereoHue,
                saturation_frame: StereoGrey, rig: Rig, proj: ModelProjection | None = None) -> np.ndarray:
    """(2,) per camera: how much purer ONE pose's body (inner points on a target hue) is in colour than
    the photo at the same points — the median saturation of the image there (`saturation_frame`,
    `appearance.stereo_saturation`) over the photo's median (`model.inner_saturation`); nan in a camera
    with fewer than `MIN_BODY` body points or where the photo's carries no saturation. Saturation does
    not move with the light's gain, and what lies between the camera and a creature — haze, blur into
    the water beside it, glare — only dilutes its colour: the renderer's and the harbour's creatures,
    same photo or another individual's, read 0.74-1.11 at their answers (tuned, both generators). A
    look-alike of another species in a purer colour of the creature's hue reads more (renderer held-out
    6 nulls 2431, 2467 and held-out 4 null 2023: the orange crab under the pale squid's model, 1.37-1.42;
    harbour held-out 7 null 2605, a crab under a squid's model, 1.39)."""
    out = np.full(2, np.nan)
    for k, ps, sat in _body_samples(R, t, alpha, model, model.inner_saturation, frame, saturation_frame, rig, proj):
        if np.median(ps) > 0:
            out[k] = float(np.median(sat)) / float(np.median(ps))
    return out


def _body_samples(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, photo: np.ndarray,
                  frame: StereoHue, planes: StereoGrey, rig: Rig, proj: ModelProjection | None = None
                  ) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """ONE pose's body as `body_relief` and `body_purity` read it: per camera k (0 left, 1 right) with at
    least `MIN_BODY` inner points on a target hue (nearest pixel, as the fitness reads), (k, the photo's
    per-point values `photo` (N_in,) there as float64, `planes`' values at them); none when the model
    carries no such values (a model built without a photo)."""
    if len(photo) != len(model.inner_uv):
        return []
    p = projected(R, t, alpha, model, rig, proj)
    target = target_hue_lut(model.target_hues)
    out = []
    for k, (uv_in, hue, plane) in enumerate(((p.inner_left[0], frame.left, planes.left),
                                             (p.inner_right[0], frame.right, planes.right))):
        ri, ci, inside = nearest_pixel(uv_in, hue.shape)
        body = inside & target[np.where(inside, hue[ri, ci], HUE_BINS)]
        if body.sum() >= MIN_BODY:
            out.append((k, np.asarray(photo, np.float64)[body], plane[ri[body], ci[body]]))
    return out


def _chroma(uv: np.ndarray, hue: np.ndarray, ab: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """At (N, 2) pixel coordinates (nearest pixel): a*b* (N, 2) and hue (N,) (NO_HUE outside the image)."""
    ri, ci, inside = nearest_pixel(uv, hue.shape)
    return ab[ri, ci].astype(np.float64), np.where(inside, hue[ri, ci], HUE_BINS).astype(np.int16)


def off_water(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, frame: StereoHue,
              chroma: StereoChroma, rig: Rig, edge: float, water: np.ndarray | None = None,
              proj: ModelProjection | None = None) -> np.ndarray:
    """(2,) per camera: the share of ONE pose's outer points S_out that land on hue, off the target's
    hues, and more than `edge` a*b* units (a colour edge: `[fitness] contour_chroma`) from the
    image's water colour (`water_chroma`): on another object, not on the water. A model shrunk
    inside a larger object of another kind (renderer null 1849: a squid's model on a fish's brown
    band) has its outline there; a creature's lies on water, foam or glints (no hue). `water`: the
    pair's `stereo_water` (computed when None)."""
    p = projected(R, t, alpha, model, rig, proj)
    target = target_hue_lut(model.target_hues)
    water = stereo_water(model, frame, chroma) if water is None else water
    out = np.zeros(2)
    for k, (uv_out, hue, ab) in enumerate(((p.outer_left[0], frame.left, chroma.left),
                                           (p.outer_right[0], frame.right, chroma.right))):
        if not len(uv_out):
            continue
        col, h = _chroma(uv_out, hue, ab)
        off = (h < HUE_BINS) & ~target[h]
        far = np.linalg.norm(col - water[k], axis=1) > edge
        out[k] = float((off & far).sum()) / len(uv_out)
    return out
