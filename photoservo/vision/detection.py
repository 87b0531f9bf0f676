"""Detection (method step 3's fitness turned into a decision): is a candidate pose the creature?

The fitness a creature scores depends on the images — light, colour cast, shading, highlights,
foam, how many pixels carry hue at all — so a fixed fitness level calibrated on one renderer
does not carry to another or to real photos. The decision is made relative to the pair itself:
`null_scores` places the same model, at the candidate's depth, tilt and scale, at poses in the
same pair where the candidate is not (off its footprint, any heading), each placement the best
of a few small jitters (the candidate itself is the best of a search, its null should be the best
of a little search too). The candidate's `contrast` is how far it stands above that null on the
way to a perfect score,

    contrast = (S - q) / (1 - q),   S: the candidate's detection score,  q: the null's median,

and found = contrast >= min_contrast, beside the outline check (few outer points on target hue).
A brighter, darker or colour-cast copy of a pair moves S and q together.

Another individual's photo turns the creature's hues by a whole-body offset (the harbour's other
individuals: up to 16 OpenCV steps against the tolerance of 10), so its fit can stand a little under
`min_contrast` on hue while the photo's brightness layout shows inside it. Where hue bounds the target
(not the contour rule's regime), a candidate whose layout is the photo's by both appearance cues (each
at least `min_appearance`, as for the outline's excuse below; Pearson correlations, invariant to the
image's gain and offset) needs no contrast level: its hue must only stand above what a search of the
pair at its scale finds elsewhere (`standing` > 0). Harbour 2137 and 2327 (other individuals' squid
and crab: contrast 0.29 and 0.26 at fits 3.9 and 0.7 % off, cues 0.52 / 0.55 and 0.38 / 0.49) pass; a
float or a leaf of one hue has no layout to show. In the contour regime the contrast is not a hue
offset's: there the excuse found the aloe pair's upright leaf on a neighbouring leaf (left image, seed
3), so it does not apply.

Candidates of different scales are compared by their `standing`: the same formula against what
a search of the whole pair at the candidate's apparent scale would find where the creature is
not — the (1 - 1/n) quantile, n the number of places the model fits in the image without overlap
(`placements`), of a second null (`WIDE_PLACEMENTS` draws) whose placements keep the candidate's
apparent size but take any depth of the search volume (a search meets the model at every depth;
at the candidate's own depth alone, a small fit on a spot of the colour far behind the creature
finds nothing else red and looked better than the creature, whose depth holds more of its
colour). A model shrunk to a few pixels fits thousands of places and some small spot of its
colour somewhere; the creature's own scale fits a few dozen. A candidate standing at or below 0
does not pass: what a search of the pair at its scale finds where it is not scores as well, so it
cannot be told from a look-alike of its shape (the aloe pair's upright leaf at 0.6x: fits a third of
its size on a neighbouring leaf's tip, 0.53-0.56 where the null's draws on the plant reach 0.55,
standing -0.06 to -0.03 in 3 of the 5 seeds that found it there; the answers of the synthetic sets'
targets stand 0.25 or more, the motorcycle's and the aloe pot's 0.49 or more).

Where the contour rule bounds the target (`frame.chroma`: its hues everywhere, a plant before a
patterned backdrop) hue cannot tell the target from any stuff of its colour, and a pale target
barely carries hue. There a candidate's inner points must lie on the photo's colours over hue and
saturation (`vision/colour_cells.py`, down to saturation 12) at least as often as the same model's
placements elsewhere at their 0.9 quantile (`photo_colours`; the pair compared with itself). The aloe
pair's neighbouring-leaf fits 0.40-0.45 against 0.64-0.69; every answer on the right object of both
real pairs 0.86-0.98 against <= 0.69.

The outline test alone rejects true creatures whose outline differs from the photo's (another
individual's fins and proportions, a rim the photo cuts off, a real target cut off by what lies
in front of it). A candidate whose outer points spill (up to `max_outer_if_appearance`) still
passes when the brightness layout inside it is the photo's by both appearance cues
(`vision/appearance.py`, `appearance_pair`): the grey correlation over the inner points on
target hue and the body's brightness correlation, each at least `min_appearance`. Both are
Pearson correlations, invariant to the image's gain and offset.

Which outer points spill (`contour.outline_spill`, `[estimator] outline_distinctive`): blur and
chroma loss blend a creature into the water over a pixel or two, so its rim takes hues between
the two — within the hue tolerance of the target's hues, but hues the creature itself barely
holds — and another individual's outline differs from the photo's by such a rim's width. A
look-alike under the model instead goes on past the model's outline: the same stuff, the same
colour, on both sides. Each outer point on a target hue is judged against its nearest inner
point as the contour rule pairs them (`vision/contour.py`; the pair's chroma: the image compared
with itself, not with the photo):

    target hue on both, no colour edge between (pair judged):  1   (the target goes on)
    across a colour edge:                                      0   (off the target)
    otherwise (too close to judge, or the inner point off):    w(h) = M(h) / (M(h) + I(h))

w the distinctive weight of its hue (`silhouette.distinctive_weight`: M, I the hue shares of the
photo-model's inner points and of the pair's hued pixels): a rim hue the creature barely holds
weighs ~0, the creature's own ~1. Where the contour rule is on (`frame.chroma`), it alone counts
(only the flat points spill). Held-out harbour null 1557 (a fish's model on an orange squid) is
what the weight alone let through: the squid's orange, a hue the fish's photo barely holds, goes
on past the fish's outline (0.106 weighted, 0.149 here, against 0.11).

A candidate must also have its parts there (`vision/parts.py`): the photo-model's inner points
fall into compact parts, and at most `max_absent_parts` of the model's parts may land on hue
with fewer than half their points on a target hue — a crab's model squeezed onto a squid or a
buoy of its colour matches on its body while its legs lie on water; foam over a creature leaves
its parts without hue, which does not count against it, nor does a part straddling a foam band's
pale, blurred edge (`parts.foam_marked`, `[estimator] foam_part_share`). Of two or more absent
parts none may lie on bare water (`vision/bare_parts.py`, `[estimator] bare_water_z`): a float or
a leaf of the creature's one hue under its model leaves the model's arms on pixels of the water's
own colour beside it, where a true creature's blurred arms leave a trace of the body's colour and
another individual's displaced limb leaves one part. Another individual's limb may leave one part
on bare water and a second absent beside it (its tentacle shorter or lying elsewhere than the
photo's): a candidate with ONE part on bare water whose brightness layout inside is the photo's by
both appearance cues (each at least `min_appearance`, as for the outline's excuse) is not rejected.
A float or a leaf of one hue has no layout of the photo's to show (harbour nulls 1567, 1582, 1609,
1663, 1693, 2032, 2056, 2092, 2209, 2221: one part bare, the smaller cue -0.17 to 0.17); the other
individuals' squids harbour 1441 and 1453 show theirs (0.29 / 0.34 and 0.40 / 0.45 at fits 1.6 and
1.1 % off). Two parts on bare water are a model wider than what lies under it whatever its layout
(harbour null 2275: another species under a squid's model, both arm parts bare, cues 0.29 / 0.54).
Where hue bounds the target, another individual's crab may lose ONE part beyond `max_absent_parts`
(its legs lie where the photo's do not: other proportions) when none of its absent parts lies on bare
water and its outline stays clean, at most `CLEAN_OUTLINE` of `max_outer_on_target` on target hue:
the creature under the model ends where the model does and its legs leave the body's colour, not the
water's, under the model's (harbour 1235, 2123, 2351, 2501, 2555: 3 of 12 absent, none bare, outline
0.000-0.022). A look-alike of another species under a crab's model with three legs absent and none
bare spills over the outline (harbour nulls 1565, 1577, 1625: 0.070-0.099) and a float leaves them on
bare water.

Where the contour rule bounds the target (`frame.chroma`: the target's hues everywhere), the outline
is seen only through the outer points it judges: those at least `contour.MIN_GAP_PX` from their inner
neighbour in the image. A fit a few pixels long has none judged, so nothing spills and nothing shows
its outline either: its score is its inner points on their hues, which any spot of the creature's
colour gives at that size (harbour null 1812: a fish's model 14 px long on a leaf on water of the
fish's hues, contrast 0.51, outline 0 of 0). Such a candidate passes only when the rule judges at
least `MIN_JUDGED_SHARE` of its outer points in both cameras — not a size threshold of one generator
but the outline test's own condition for saying anything.

Where hue bounds the target, a candidate's outline must lie on the water (or on what carries no hue:
foam, glints), not on another object: at most `MAX_OFF_WATER` of its outer points (in the camera
with fewer) may land on hue, off the target's hues and a colour edge (`[fitness] contour_chroma`)
away from the image's own water colour, the median a*b* of its pixels off the target's hues
(`bare_parts.off_water`). A model shrunk inside a larger object of another kind whose colour it
partly shares (renderer null 1849: a squid's model on a fish's brown band, outline on the fish's
yellow and green) passes the outline test, whose spill counts target hues only.

Where hue bounds the target, the body must also stand a colour edge off the water around it: the
a*b* distance between the candidate's body (inner points on a target hue) and the water beside it
(outer points on hue off the target's hues) at least `[fitness] contour_chroma` in one camera
(`bare_parts.body_gap`). Hue is the angle of a*b*; a dull object a few units off the water's colour
turns that angle across the tolerance with a small shift, and then agrees with a creature's model
hue for hue while it is, to the image, nearly the water (harbour held-out 5 null 2266: a squid's
model 55 mm long on a brown leaf, contrast 0.42, outline clean, 1 part absent; the body 9.8 and
11.4 units off the water). The same colour edge the contour rule and `off_water` use.

Where hue bounds the target, the body must also vary in brightness as the photo does: the coefficient
of variation of the image's brightness over the body points, over the photo's at the same points, at
least `MIN_BODY_RELIEF` (a half) in the larger camera (`bare_parts.body_relief`). A leaf or a float of
one flat colour under a squid's model varies far less than the photo's mottled, shaded body (harbour
held-out 2 null 1861, a leaf on blue water, 0.40; held-out 5 null 2266 0.46), a creature as much or
more (the tuned answers 0.88 or more: shading adds to the photo's own layout; blur takes little). Both
ratios are of an image with itself, so the light's gain cancels.

Where hue bounds the target, the body must also be no purer in colour than the photo: the median
saturation (HSV's S) of the image at the body points over the photo's at the same points at most
`MAX_BODY_PURITY` in one camera (`bare_parts.body_purity`). Saturation does not move with the light's
gain, and what lies between the camera and a creature (haze, blur into the water, glare) only dilutes
its colour; another individual's photo is coloured differently, but the creatures' answers read 0.74-1.11
(tuned, both generators). Another species of the creature's hue in a purer colour reads more: the
renderer's vivid orange crab under the pale squid's model (held-out 6 nulls 2431, 2467 and held-out 4
null 2023: 1.37-1.42; contrast 0.58-0.67, outline, parts, water, colour edge and relief all pass, the crab
mottled as the squid is), the harbour's crab under a squid's model (held-out 7 null 2605: 1.39).

The appearance excuse is for an outline that differs from the photo's by a little (another
individual's fins, a rim): where hue bounds the target it holds only while the blob of the target's
hues under the candidate ends about where its model does — in the camera where it goes on less,
past the model's outline (and a rim of a twentieth of its size) by at most `MAX_BLOB_BEYOND` of the
footprint's area (`footprint.blob_beyond`). A model fitted onto part of something larger of the
target's colour spills because the rest of that thing goes on past it (harbour null 2001: a fish's
model on a squid's mantle, its outline half on the squid, appearance cues 0.26 and 0.34; the
squid's head and arms go on past the snout by 1.3 times the footprint). Only the excuse is judged
so: a creature with a look-alike of its hues touching it has a clean outline and may go on far
(renderer 1431 at the truth: a crab's claw at a fish's nose, 0.43 and 1.16).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from photoservo.geometry import rotation_from_heading_tilt
from photoservo.vision.appearance import StereoGrey, appearance, body_layout, body_points
from photoservo.vision.bare_parts import bare_counts, body_gap, body_purity, body_relief, off_water
from photoservo.vision.colour_cells import StereoCells, cell_share
from photoservo.vision.contour import (
    TARGET_FLAT,
    StereoChroma,
    contour_counts,
    contour_counts_reference,
    judged_share,
    outline_spill,
    outline_spill_reference,
)
from photoservo.vision.fitness import (
    OUT_MISMATCH,
    FitnessParams,
    StereoHue,
    counts_compiled,
    counts_reference,
    fitness,
    project_model,
)
from photoservo.vision.footprint import blob_beyond
from photoservo.vision.parts import absent_parts, model_parts
from photoservo.vision.photo_model import PhotoModel
from photoservo.vision.pose_search import Candidate, aspect_map
from photoservo.vision.rig import Rig
from photoservo.vision.silhouette import distinctive_weight

if TYPE_CHECKING:
    from photoservo.vision.estimator import EstimatorParams

# placements of the standing's null at any depth: its (1 - 1/n) quantile, n the image's model-sized
# places (100 to thousands), is the largest of the draws when n exceeds them, so few draws make
# the standing too high, most for the fits with the most places (the smallest): on the real pair,
# against 2000 draws, by 0.03-0.2 (sd 0.05-0.14) from 40 draws, 0.01-0.09 (sd <= 0.08) from 160,
# 0-0.04 (sd <= 0.035 but one 0.07) from 320
WIDE_PLACEMENTS = 320
# the outline check's reference: this quantile of the null placements' shares of outer points on
# target hue. On water every placement gives 0 (as the median did); where the background holds
# the target's hues in patches (the real pair's wood, the harbour's speckled water) a creature's
# own surroundings vary as widely as the placements' do, and the outline can only call a share
# a spill when the background seldom gives as much
OUTLINE_NULL_QUANTILE = 0.9
# batches of 8 x placements random origins `null_scores` draws at most to find its placements
NULL_DRAW_BATCHES = 16
# where the contour rule bounds the target, the least share of a candidate's outer points it must
# judge in each camera (`contour.judged_share`) for the outline to have been seen at all (module
# docstring). Harbour null 1812: a fish's model fitted 14 px long on a leaf, 0 judged; the answers
# of the contour-regime targets (harbour, many-hued fish, the real pair's 54 runs) 0.31-1.0
MIN_JUDGED_SHARE = 0.1
# where hue bounds the target, the largest share of a candidate's outer points (in the camera with
# fewer) that may lie on another object: on hue, off the target's hues and a colour edge away from
# the image's water (`bare_parts.off_water`). Renderer null 1849 (a squid's model inside a fish's
# brown band) 0.31 and 0.36; every candidate that passes in the target scenes of tuned, held-out 1
# and 2 on both generators <= 0.16 (harbour 1047)
MAX_OFF_WATER = 0.25
# where hue bounds the target, the largest share of a candidate's footprint by which the blob of target
# hue under it may go on past its outline (the camera where it goes on less: `footprint.blob_beyond`)
# for an outline that spills to be excused by the appearance cues: harbour null 2001 (a fish's model on
# a squid's mantle) 1.27; at the truth pose of the target scenes of tuned and held-out 1, 2, 4 (both
# generators) <= 0.13 but renderer 1431 (a look-alike touching the fish) 0.43
MAX_BLOB_BEYOND = 0.5
# where the contour rule bounds the target: placements of the model elsewhere (its depth and scale, any heading)
# at which the photo's colours are counted (`photo_colours`), their random stream (apart from the nulls' own)
# and the quantile of their shares the candidate's must reach (the outline check's reference quantile)
COLOUR_PLACEMENTS = 200
COLOUR_STREAM = 7
COLOUR_NULL_QUANTILE = OUTLINE_NULL_QUANTILE
# (the body's colour edge to the water, `bare_parts.body_gap`, is `[fitness] contour_chroma`: no constant of its own)
# where hue bounds the target, the least ratio of the body's brightness variation to the photo's at the same
# points, in the larger camera (`bare_parts.body_relief`): harbour leaf nulls 1861 (held-out 2) and 2266
# (held-out 5) under a squid's model 0.40, 0.46; the tuned targets' answers (both generators) 0.88 or more:
# the body varies at least half as much as the photo's does
MIN_BODY_RELIEF = 0.5
# where hue bounds the target, a candidate with ONE part beyond `max_absent_parts` absent and none on bare
# water passes its parts when its outline spills at most this share of `max_outer_on_target` (module
# docstring): another individual's crabs harbour 1235, 2123, 2351, 2501, 2555 at fits 0.5-3.4 % off
# 0.000-0.022; look-alikes of another species (harbour nulls 1565, 1577, 1625) 0.070-0.099
CLEAN_OUTLINE = 0.25
# where hue bounds the target, the most by which the body's median saturation may exceed the photo's at the same
# points, in both cameras (`bare_parts.body_purity`): the renderer's orange crab under the pale squid's model
# (held-out 6 nulls 2431, 2467, held-out 4 null 2023) 1.37-1.42, the harbour's crab under a squid's model (held-out
# 7 null 2605) 1.39; the tuned targets' answers (both generators, same photo or another individual's) 1.11 or less
MAX_BODY_PURITY = 1.25


def confidence(contrast: float, params: EstimatorParams) -> float:
    """Logistic confidence that a candidate standing `contrast` above its null is the target."""
    if not np.isfinite(contrast):
        return 0.0
    return 1.0 / (1.0 + math.exp(-(contrast - params.min_contrast) / params.confidence_scale))


def null_scores(c: Candidate, model: PhotoModel, frame: StereoHue, rig: Rig, fit_params: FitnessParams,
                rng: np.random.Generator, placements: int = 40, jitters: int = 6,
                depths_mm: tuple[float, float] | None = None, outer: bool = True,
                cues: OutlineCues | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Detection scores (fitness, cameras combined by min) of the candidate's model where the
    candidate is not: `placements` poses at the candidate's depth, tilt and alpha with the model
    origin at random pixels of the left image at least one apparent model length (at most 0.4 of
    the image's shorter side) away from the candidate's and inside the right image too, any heading; each the best of `jitters` variants (origin within a fifth of the
    length, heading +- 20 deg, alpha +- 10 %). Returns the (placements,) scores and the shares of
    outer points on target hue at every variant (`outer_share`); empty when the image has no room
    off the candidate. `depths_mm` (near, far): each placement at its own depth instead (inverse
    depth uniform between them) with alpha scaled to keep the candidate's apparent size — the
    model as a search of the pair at the candidate's apparent scale meets it anywhere in depth —
    and off the candidate in the right image too (at another depth the two differ).
    `outer` False: the outer shares are not counted (an empty array); `cues`: `outer_share`'s."""
    strict = dataclasses.replace(fit_params, combine="min")
    K = rig.left.K
    t = np.asarray(c.position_mm, float)
    z = float(t[2])
    length = K[0, 0] * max(model.size_px) / (c.alpha * z)  # apparent longest side (px)
    uv, zs = np.zeros((0, 2)), np.zeros(0)
    # a near model leaves little room off it and inside both images (under 1 % of the draws may
    # land there): draw again until `placements` do (at most NULL_DRAW_BATCHES batches; most models
    # fill them from the first, as the same draws did before), so its null is not one or two
    # placements or none (an empty null made q = 0 and the contrast the score itself)
    for _ in range(NULL_DRAW_BATCHES):
        more_uv, more_zs = _null_origins(t, length, rig, rng, 8 * placements, depths_mm)
        uv, zs = np.concatenate([uv, more_uv]), np.concatenate([zs, more_zs])
        if len(uv) >= placements:
            break
    uv, zs = uv[:placements], zs[:placements]
    if not len(uv):
        return np.zeros(0), np.zeros(0)
    n = len(uv) * jitters
    uv = np.repeat(uv, jitters, axis=0) + rng.uniform(-0.2, 0.2, (n, 2)) * length
    zs = np.repeat(zs, jitters)
    psi = np.repeat(rng.uniform(-math.pi, math.pi, len(uv) // jitters), jitters) + rng.uniform(-0.35, 0.35, n)
    R, pos = _placed(c, uv, zs, psi, K)
    alpha = c.alpha * z / zs * rng.uniform(0.9, 1.1, n)
    f = fitness(R, pos, alpha, model, frame, rig, strict)
    shares = outer_share(R, pos, alpha, model, frame, rig, fit_params, cues) if outer else np.zeros(0)
    return f.reshape(-1, jitters).max(axis=1), shares


def _placed(c: Candidate, uv: np.ndarray, zs: np.ndarray, psi: np.ndarray, K: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """The candidate's model turned by `psi` (rad, about its normal) with its origin at left-image
    pixels `uv` (N, 2) and depths `zs` (N,) mm: (R (N, 3, 3) with the candidate's aspect, position (N, 3) mm)."""
    n = len(uv)
    R = np.asarray(c.R)[None] @ rotation_from_heading_tilt(psi, np.zeros(n), np.zeros(n))
    R = aspect_map(R, np.full(n, c.aspect))
    pos = np.column_stack([(uv[:, 0] - K[0, 2]) * zs / K[0, 0], (uv[:, 1] - K[1, 2]) * zs / K[1, 1], zs])
    return R, pos


def photo_colours(c: Candidate, model: PhotoModel, cells: StereoCells, rig: Rig, seed: int = 0
                  ) -> tuple[float, float]:
    """The candidate's share of inner points on the photo's colours (`colour_cells.cell_share`, the worse
    camera) and the `COLOUR_NULL_QUANTILE` quantile of that share at `COLOUR_PLACEMENTS` placements of its
    model elsewhere in the pair (its depth and scale, any heading, off its footprint: `_null_origins`;
    stream `COLOUR_STREAM` of `seed`); nan, nan where no placement fits."""
    rng = np.random.default_rng([seed, COLOUR_STREAM])
    K = rig.left.K
    t = np.asarray(c.position_mm, float)
    length = K[0, 0] * max(model.size_px) / (c.alpha * float(t[2]))
    uv, zs = _null_origins(t, length, rig, rng, 8 * COLOUR_PLACEMENTS, None)
    uv, zs = uv[:COLOUR_PLACEMENTS], zs[:COLOUR_PLACEMENTS]
    if not len(uv):
        return math.nan, math.nan
    R, pos = _placed(c, uv, zs, rng.uniform(-math.pi, math.pi, len(uv)), K)
    null = cell_share(R, pos, np.full(len(uv), c.alpha), model.inner_uv, cells, rig)
    own = cell_share(c.R_model, c.position_mm, c.alpha, model.inner_uv, cells, rig)
    return float(own[0]), float(np.quantile(null, COLOUR_NULL_QUANTILE))


def _null_origins(t: np.ndarray, length: float, rig: Rig, rng: np.random.Generator, draws: int,
                  depths_mm: tuple[float, float] | None) -> tuple[np.ndarray, np.ndarray]:
    """Of `draws` random model origins (left-image pixels, depth), those `null_scores` may use:
    at least one apparent model length `length` (px; at most 0.4 of the image's shorter side) off
    the candidate at `t` (left camera, mm) and inside the right image too (and off the candidate
    there when each has its own depth, inverse depth uniform in `depths_mm`). Returns uv (N, 2)
    px and depths (N,) mm."""
    K = rig.left.K
    z = float(t[2])
    u0 = K[0, 0] * t[0] / z + K[0, 2]
    v0 = K[1, 1] * t[1] / z + K[1, 2]
    W, H = rig.left.width, rig.left.height
    m = 0.5 * min(length, 0.8 * min(W, H))
    uv = rng.uniform([m, m], [max(m + 1, W - m), max(m + 1, H - m)], size=(draws, 2))
    # off the footprint; a model too large for that (longer than ~0.4 of the image) at least that far
    far = np.hypot(uv[:, 0] - u0, uv[:, 1] - v0) >= min(length, 0.4 * min(W, H))
    zs = np.full(len(uv), z)
    if depths_mm is not None:
        zs = 1.0 / rng.uniform(1.0 / depths_mm[1], 1.0 / depths_mm[0], len(uv))
    # ...and where the right camera sees it too (near the rig the disparity is large)
    X = np.column_stack([(uv[:, 0] - K[0, 2]) * zs / K[0, 0], (uv[:, 1] - K[1, 2]) * zs / K[1, 1], zs])
    Xr = X @ rig.R.T + rig.T
    Kr = rig.right.K
    ur = Kr[0, 0] * Xr[:, 0] / Xr[:, 2] + Kr[0, 2]
    vr = Kr[1, 1] * Xr[:, 1] / Xr[:, 2] + Kr[1, 2]
    seen = far & (ur >= m) & (ur <= rig.right.width - m) & (vr >= m) & (vr <= rig.right.height - m)
    if depths_mm is not None:  # at another depth, off the candidate in the left image is not off it in the right
        tr = rig.R @ t + rig.T
        seen &= np.hypot(ur - (Kr[0, 0] * tr[0] / tr[2] + Kr[0, 2]),
                         vr - (Kr[1, 1] * tr[1] / tr[2] + Kr[1, 2])) >= min(length, 0.4 * min(W, H))
    return uv[seen], zs[seen]


def placements(c: Candidate, model: PhotoModel, rig: Rig) -> float:
    """How many places of the left image a search could try the candidate's model at without
    overlap (>= 1): the image's area over the model's apparent area (its mask at the candidate's
    apparent scale fx / (alpha z))."""
    s = float(rig.left.K[0, 0]) / (c.alpha * float(np.asarray(c.position_mm)[2]))
    area = float(np.count_nonzero(model.mask)) * s * s
    return max(1.0, rig.left.width * rig.left.height / max(area, 1.0))


@dataclass(frozen=True)
class OutlineCues:
    """What the distinctive outline (module docstring) reads besides the hue: `weight`, the (256,)
    lookup `silhouette.distinctive_weight` of the pair, and `chroma`, the pair's a*b* planes
    (`contour.stereo_chroma`)."""

    weight: np.ndarray
    chroma: StereoChroma


def outer_share(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, model: PhotoModel, frame: StereoHue, rig: Rig,
                fit_params: FitnessParams, cues: OutlineCues | None = None) -> np.ndarray:
    """(P,): the largest share, over the two cameras, of outer points S_out on target hue — under
    the contour rule (`frame.chroma` set, vision/contour.py) of those on a target hue without a
    colour edge to their inner neighbour, where the target goes on past the outline; with `cues`
    elsewhere, the distinctive outline's spill (`contour.outline_spill`, module docstring)."""
    if frame.chroma is not None:
        R, t, alpha = np.reshape(R, (-1, 3, 3)), np.reshape(t, (-1, 3)), np.reshape(alpha, -1).astype(float)
        spill = (contour_counts_reference if fit_params.kernel == "numpy" else contour_counts)(
            R, t, alpha, model, frame, rig, fit_params)[:, :, TARGET_FLAT]
    elif cues is not None:
        R, t, alpha = np.reshape(R, (-1, 3, 3)), np.reshape(t, (-1, 3)), np.reshape(alpha, -1).astype(float)
        spill = (outline_spill_reference if fit_params.kernel == "numpy" else outline_spill)(
            R, t, alpha, model, frame, cues.chroma, rig, fit_params, cues.weight)
    else:
        spill = (counts_reference if fit_params.kernel == "numpy" else counts_compiled)(
            R, t, alpha, model, frame, rig, fit_params)[:, :, OUT_MISMATCH]
    return spill.max(axis=1) / max(1, len(model.outer_uv))


@dataclass(frozen=True)
class Detection:
    """Is a candidate the target? `score`: the stereo fitness with the two cameras combined by
    their minimum (`[fitness] combine = "min"`), so a look-alike seen by one camera only, or a
    pose that fits one image and not the other, cannot pass on the strength of one camera (the GA
    itself optimises the configured combination). `null_level`: the median of `null_scores`;
    `contrast` = (score - null_level) / (1 - null_level) (module docstring). `outer_on_target`:
    the largest share, over the two cameras, of outer points S_out landing on target hue (the
    distinctive outline's spill where `detect` has the pair's chroma: module docstring) beyond
    what the pair's own background gives, (o - o_null) / (1 - o_null) with o_null the
    `OUTLINE_NULL_QUANTILE` quantile of the shares at the null placements (0 for a creature whose
    hues the water lacks; near 1 for a many-hued one whose hues include the water's; in between
    where the background holds the target's hues in patches) — the creature's outline must end
    where the model's does (a buoy or another species of the same colour usually spills over).
    passed = (contrast >= min_contrast or (layout and hue bounds the target))
             and (outer_on_target <= max_outer_on_target or excused)
             and not (absent_parts > max_absent_parts and not legs_elsewhere)
             and not (absent >= 2 and bare_parts >= 1 and not (bare_parts == 1 and layout))
             and not outline_judged < MIN_JUDGED_SHARE and not off_water > MAX_OFF_WATER
             and standing > 0 and not photo_colours < photo_colours_null
             and not body_gap < contour_chroma and not body_relief < MIN_BODY_RELIEF
             and not body_purity > MAX_BODY_PURITY,
    excused = outer_on_target <= max_outer_if_appearance and layout and not blob_beyond > MAX_BLOB_BEYOND,
    legs_elsewhere = hue bounds the target and no absent part on bare water in any camera missing it
                     and outer_on_target <= CLEAN_OUTLINE · max_outer_on_target
                     and absent_parts <= max_absent_parts but for one part,
    layout = appearance, body_layout >= min_appearance
    (`appearance_pair`; module docstring);
    confidence = logistic((contrast - min_contrast) / confidence_scale)
                 · (1 if excused else logistic((max_outer_on_target - outer_on_target) / 0.02)).
    `threshold`: the detection score that would just pass in this pair (the tracker's per-frame
    test). `standing`: (score - q_b) / (1 - q_b) with q_b the (1 - 1/n) quantile of the null at
    any depth (at least the null's median), n = `placements` (module docstring): how the
    candidate compares with the best a search of this pair at its apparent scale finds
    elsewhere; candidates are ranked by it. `appearance`, `body_layout`: `appearance_pair` (nan
    when not measured). `absent_parts`: the share of the model's parts absent in the worse camera
    (`vision/parts.py`: of all its parts, those under foam are not absent; nan when no part lands
    on hue). `bare_parts`: how many of the absent parts lie on bare water in both cameras
    (`vision/bare_parts.py`; 0 when not judged: no grey or chroma images, `bare_water_z` 0), with
    `absent` the worse camera's count of absent parts (of two or more, none may be bare).
    `outline_judged`: where the contour rule bounds the target, the worse camera's share of outer
    points it judges (`contour.judged_share`; nan elsewhere): below `MIN_JUDGED_SHARE` the outline was
    not seen and the candidate does not pass (module docstring). `off_water`: where hue bounds the
    target, the smaller camera's share of outer points on another object (`bare_parts.off_water`;
    nan elsewhere), at most `MAX_OFF_WATER` to pass. `blob_beyond`: where hue bounds the target and
    the outline passes by the appearance excuse alone, the smaller camera's share of the footprint by
    which the blob of target hue under the candidate goes on past its outline (`footprint.blob_beyond`;
    nan where not measured), at most `MAX_BLOB_BEYOND` for the excuse to hold. `body_gap`: where hue
    bounds the target, the larger camera's a*b* distance between the body and the water beside it
    (`bare_parts.body_gap`; nan elsewhere or where a camera cannot judge), at least `[fitness]
    contour_chroma` (a colour edge) to pass. `body_relief`: where hue bounds the target, the larger
    camera's ratio of the body's brightness variation to the photo's at the same points
    (`bare_parts.body_relief`; nan elsewhere or where no camera judges), at least `MIN_BODY_RELIEF`
    to pass. `body_purity`: where hue bounds the target, the smaller camera's ratio of the body's median
    saturation to the photo's at the same points (`bare_parts.body_purity`; nan elsewhere, without a
    saturation frame or where no camera judges), at most `MAX_BODY_PURITY` to pass. `on_bare_water`: the
    bare-water rule rejects it (two or more parts absent, one of them on bare water and the layout
    inside not the photo's, or two on bare water: a float or another creature under the model, not the
    creature with a part hidden or another individual's limb lying elsewhere; `candidates.ranked`).
    `photo_colours`: where the contour rule bounds the target and the pair's colour cells are given, the
    candidate's share of inner points on the photo's colours (`photo_colours`), `photo_colours_null` the
    same share's `COLOUR_NULL_QUANTILE` quantile at placements elsewhere (nan both where not judged).
    `fails_on_parts`: the contrast and every outline test pass but the candidate does not — its parts
    (too many absent, or two absent and one on bare water), or its standing or the photo's colours:
    `candidates.parted_turns` re-fits such a candidate turned."""

    score: float
    null_level: float
    contrast: float
    outer_on_target: float
    passed: bool
    confidence: float
    threshold: float
    standing: float
    appearance: float = math.nan
    body_layout: float = math.nan
    absent_parts: float = math.nan
    bare_parts: int = 0
    outline_judged: float = math.nan
    off_water: float = math.nan
    blob_beyond: float = math.nan
    on_bare_water: bool = False
    photo_colours: float = math.nan
    photo_colours_null: float = math.nan
    body_gap: float = math.nan
    body_relief: float = math.nan
    body_purity: float = math.nan
    fails_on_parts: bool = False


def appearance_pair(c: Candidate, model: PhotoModel, frame: StereoHue, grey_frame: StereoGrey,
                    value_frame: StereoGrey, rig: Rig) -> tuple[float, float]:
    """The candidate's two appearance cues (`vision/appearance.py`): `appearance` (the photo's grey
    at the inner points landing on target hue, both cameras averaged) and `body_layout` (its
    brightness at the inner points inside the outline, the worse camera); nan where undefined."""
    scale = float(rig.left.K[0, 0]) / (c.alpha * float(np.asarray(c.position_mm)[2]))  # image px per photo px
    a = appearance(c.R_model, c.position_mm, c.alpha, model, frame, grey_frame, rig)
    b = body_layout(c.R_model, c.position_mm, c.alpha, model, value_frame, rig, body_points(model, scale))
    return a, b


def detect(c: Candidate, model: PhotoModel, frame: StereoHue, rig: Rig, fit_params: FitnessParams,
           p: EstimatorParams, seed: int = 0, grey_frame: StereoGrey | None = None,
           value_frame: StereoGrey | None = None, parts: np.ndarray | None = None,
           chroma: StereoChroma | None = None, weight: np.ndarray | None = None,
           water: np.ndarray | None = None, foam: StereoHue | None = None,
           cells: StereoCells | None = None, saturation_frame: StereoGrey | None = None) -> Detection:
    """The detection test of one candidate (see `Detection`); `seed` draws the null placements;
    `grey_frame` / `value_frame` (`appearance.stereo_grey` / `stereo_value` of the pair): the
    appearance cues that may excuse an outline spill (module docstring; without them, none);
    `parts`: the model's `parts.model_parts` (computed when None); `chroma`
    (`contour.stereo_chroma` of the pair): the distinctive outline (module docstring; without it,
    every outer point on a target hue spills wholly), with `weight` its hues' lookup
    (`silhouette.distinctive_weight` of the pair; computed when None); `water`: the pair's water colour
    (`bare_parts.stereo_water`; computed when None), for the outline on another object; `foam`: the
    pair's hue with its foam marked (`parts.foam_marked`), which the parts check and the bare-water
    rule read instead of `frame`: a part with `foam_part_share` of its points on foam is not judged
    (module docstring); `cells`: the pair's pixels on the photo's colours (`colour_cells.stereo_cells`),
    which, where the contour rule bounds the target, the candidate's inner points must lie on as often as
    the model's placements elsewhere do at their upper quantile (`photo_colours`; module docstring);
    `saturation_frame` (`appearance.stereo_saturation` of the pair): the body's colour against the photo's,
    where hue bounds the target (`bare_parts.body_purity`; without it, not judged)."""
    strict = dataclasses.replace(fit_params, combine="min")
    score = float(fitness(c.R_model, c.position_mm, c.alpha, model, frame, rig, strict)[0])
    rng = np.random.default_rng(seed)
    cues = None  # the distinctive outline (module docstring) where the contour rule does not bound the target
    if p.outline_distinctive and chroma is not None and frame.chroma is None:
        cues = OutlineCues(weight=distinctive_weight(frame.left, frame.right, model) if weight is None else weight,
                           chroma=chroma)
    null, null_outer = null_scores(c, model, frame, rig, fit_params, rng, cues=cues)
    # the look-elsewhere null of `standing`: the model at its apparent size anywhere in the volume
    # (a small fit on a spot of the colour far off matches nothing at its own depth elsewhere)
    wide, _ = null_scores(c, model, frame, rig, fit_params, rng, placements=WIDE_PLACEMENTS,
                          depths_mm=(p.z_min_mm, p.z_max_mm), outer=False)
    o_null = min(float(np.quantile(null_outer, OUTLINE_NULL_QUANTILE)), 0.99) if len(null_outer) else 0.0
    o = float(outer_share(c.R_model, c.position_mm, c.alpha, model, frame, rig, fit_params, cues)[0])
    outer = max(0.0, (o - o_null) / (1.0 - o_null))
    q = float(np.median(null)) if len(null) else 0.0
    q = min(q, 0.99)
    contrast = (score - q) / (1.0 - q)
    qb = min(float(np.quantile(wide, 1.0 - 1.0 / placements(c, model, rig))) if len(wide) else 0.0, 0.99)
    standing = (score - max(q, qb)) / (1.0 - max(q, qb))
    look = (math.nan, math.nan)
    if grey_frame is not None and value_frame is not None:
        look = appearance_pair(c, model, frame, grey_frame, value_frame, rig)
    # the brightness layout inside is the photo's by both cues (nan: no): it excuses a contrast short of
    # min_contrast (another individual's hue offset), an outline that spills a little and parts on bare
    # water (another individual's fins, rim or limb)...
    layout = bool(np.all(np.asarray(look) >= p.min_appearance))
    excused = outer <= p.max_outer_if_appearance and layout
    beyond = math.nan  # ...and, where hue bounds the target, the blob under it ends near its outline
    if excused and outer > p.max_outer_on_target and frame.chroma is None:
        beyond = float(np.min(blob_beyond(c.R_model, c.position_mm, c.alpha, model, frame, rig)))
        excused = not beyond > MAX_BLOB_BEYOND
    parts_frame = frame if foam is None else foam  # a part straddling foam is not judged (vision/parts.py)
    # the candidate's points in both cameras, projected once for the parts check and the rules below that read them
    proj = project_model(c.R_model, c.position_mm, c.alpha, model, rig)
    absent = absent_parts(c.R_model, c.position_mm, c.alpha, model, parts_frame, rig, parts, p.foam_part_share, proj)
    n_absent, bare, bare_any = 0, 0, -1  # parts on bare water (module docstring), from the pair's grey and chroma
    if p.bare_water_z > 0 and grey_frame is not None and chroma is not None:
        n_absent, bare, bare_any = bare_counts(c.R_model, c.position_mm, c.alpha, model, parts_frame, grey_frame, chroma, rig,
                                    model_parts(model.inner_uv) if parts is None else parts, p.bare_water_z,
                                    p.foam_part_share, proj)
    # where the contour rule bounds the target: how much of the outline it could judge (module docstring)
    judged = (float(judged_share(c.R_model, c.position_mm, c.alpha, model, frame, frame.chroma, rig, fit_params).min())
              if frame.chroma is not None else math.nan)
    # where hue bounds the target: how much of the outline lies on another object (module docstring)
    elsewhere = (float(off_water(c.R_model, c.position_mm, c.alpha, model, frame, chroma, rig,
                                 fit_params.contour_chroma, water, proj).min()) if frame.chroma is None and chroma is not None
                 else math.nan)
    # where hue bounds the target: how far the body stands off the water beside it, the larger camera (module docstring)
    gap = (float(np.max(body_gap(c.R_model, c.position_mm, c.alpha, model, frame, chroma, rig, proj)))
           if frame.chroma is None and chroma is not None else math.nan)
    relief = math.nan  # where hue bounds the target: the body's brightness varies as the photo's (module docstring)
    if frame.chroma is None and value_frame is not None:
        ratios = body_relief(c.R_model, c.position_mm, c.alpha, model, frame, value_frame, rig, proj)
        relief = float(np.max(ratios[np.isfinite(ratios)])) if np.isfinite(ratios).any() else math.nan
    purity = math.nan  # where hue bounds the target: the body's colour no purer than the photo's (module docstring)
    if frame.chroma is None and saturation_frame is not None:
        ratios = body_purity(c.R_model, c.position_mm, c.alpha, model, frame, saturation_frame, rig, proj)
        purity = float(np.min(ratios[np.isfinite(ratios)])) if np.isfinite(ratios).any() else math.nan
    on_bare_water = n_absent >= 2 and bare >= 1 and not (bare == 1 and layout)
    # where the contour rule bounds the target: the inner points on the photo's colours (module docstring)
    colours, colours_null = (photo_colours(c, model, cells, rig, seed) if cells is not None and frame.chroma is not None
                             else (math.nan, math.nan))
    # where hue bounds the target, the layout excuses a contrast short of its level (module docstring)
    offset_excused = layout and frame.chroma is None
    but_parts = ((contrast >= p.min_contrast or offset_excused) and (outer <= p.max_outer_on_target or excused)
                 and not judged < MIN_JUDGED_SHARE  # nan (the hue regime): not judged
                 and not elsewhere > MAX_OFF_WATER  # nan (the contour regime, no chroma): not judged
                 and not gap < fit_params.contour_chroma  # nan (as off_water, or a camera without body or water): not judged
                 and not relief < MIN_BODY_RELIEF  # nan (the contour regime, no value frame, or neither camera judges)
                 and not purity > MAX_BODY_PURITY)  # nan (the contour regime, no saturation frame, no camera judges)
    # where hue bounds the target, one part more may be absent when none lies on bare water in any camera and
    # the outline is clean: another individual's legs lying elsewhere than the photo's (module docstring)
    legs_elsewhere = (absent > p.max_absent_parts and frame.chroma is None and bare_any == 0
                      and outer <= CLEAN_OUTLINE * p.max_outer_on_target
                      and absent * (n_absent - 1) <= p.max_absent_parts * n_absent + 1e-9)  # but for one part
    parts_fail = (absent > p.max_absent_parts and not legs_elsewhere) or on_bare_water  # nan: not a reason
    passed = (but_parts and not parts_fail
              and standing > 0.0  # a search of the pair at this scale finds as good elsewhere (module docstring)
              and not colours < colours_null)  # nan (the hue regime, no cells): not judged
    outline = 1.0 if excused else 1.0 / (1.0 + math.exp(-(p.max_outer_on_target - outer) / 0.02))
    return Detection(score=score, null_level=q, contrast=contrast, outer_on_target=outer, passed=bool(passed),
                     confidence=confidence(contrast, p) * outline, threshold=q + p.min_contrast * (1.0 - q),
                     standing=standing, appearance=look[0], body_layout=look[1], absent_parts=absent,
                     bare_parts=bare, outline_judged=judged,
                     off_water=elsewhere, blob_beyond=beyond, on_bare_water=bool(on_bare_water), body_gap=gap,
                     photo_colours=colours, photo_colours_null=colours_null, body_relief=relief, body_purity=purity,
                     fails_on_parts=bool(but_parts and not passed))
