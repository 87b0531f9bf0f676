"""The acquisition's candidates after its GA islands (vision/estimator.py, method steps 4-5): each
island's head-to-tail twin (`turned_islands`), the islands near the lead turned onto the plane both
images see (`stereo_islands`), the leading fit's refinements (`refined`), the candidates ranked by
standing (`ranked`, vision/detection.py; where the contour rule scores, those whose two images lie on
two surfaces last: `same_surface_first`), the first candidate's twin chosen by the appearance cue
(`appearance_twin`), the candidates failing their outline alone tried grown (`grown_outlines`), those
failing their parts alone re-fitted at quarter turns (`parted_turns`), those whose outline spills
re-fitted turned and grown (`grown_turns`), those failing their parts alone re-fitted at quarter turns
counting the points on foam (`foam_turns`; `[estimator] foam_turns`, off in configs/default.toml), and the
first, when it passes, searched again at the depth both images see (`stereo_depth`). Each search step is a
generator yielding the GA generations it ran (`pose_search.drive` runs one to its end; the tracker spreads
them over camera frames)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Generator
from typing import TYPE_CHECKING

import numpy as np

from photoservo.vision.appearance import StereoGrey, appearance, stereo_grey
from photoservo.vision.contour import StereoChroma
from photoservo.vision.colour_cells import StereoCells
from photoservo.vision.detection import MAX_BODY_PURITY, MAX_OFF_WATER, MIN_JUDGED_SHARE, Detection, detect
from photoservo.vision.fitness import StereoHue, fitness, point_weight
from photoservo.vision.parts import absent_parts, foam_share_inner, shares_under_foam
from photoservo.vision.photo_model import PhotoModel
from photoservo.vision.pose_search import Candidate, PoseSearch
from photoservo.vision.rig import Rig
from photoservo.vision.sampling import grey
from photoservo.vision.stereo_plane import (STEREO_DEPTH_TOL, PlaneFit, align_to_plane, fit_target_plane, on_target_hue,
                                             onto_surface, pairs_other_surfaces, stereo_depth_ratio)
from photoservo.vision.twins import mask_centroid_mm, reflected_rotation, turned_about_centroid

if TYPE_CHECKING:
    from photoservo.vision.estimator import EstimatorParams


def turned_islands(firsts: list[Candidate], islands: list[tuple[str, PoseSearch]],
                   streams: list[np.random.SeedSequence], parts: np.ndarray, p: EstimatorParams
                   ) -> Generator[int, None, None]:
    """Each island's head-to-tail twin, in `firsts` in place: an island converged head-to-tail, displaced
    along the body and tilted wrong (a crab beside a look-alike, the other individual's legs), has its
    turned twin (`PoseSearch.turned_steps`, tilt +- ISLAND_TURN_TILT_DEG, a short GA on the island's
    stream in `streams`) kept when it fits at least `island_turn_gain` better; twins that fit alike (a
    squid of one hue) are the appearance cue's (`appearance_twin`). Tried only where the twin can
    matter: for the islands whose fit has more than `max_absent_parts` of its parts absent
    (`parts.absent_parts`, `parts` the model's labels: a fit head-to-tail has its parts where the photo
    has others; a fit with its parts in place turned by fitness alone went onto a piece: harbour 1036)
    and lies within `island_turn_within` of the best island's fitness (a fit further below is another
    thing's or a piece's). One generation per step."""
    if p.island_turn_gain >= 1.0 or not firsts:
        return
    reach = max(c.fitness for c in firsts) - p.island_turn_within
    for k, ((_, search), s) in enumerate(zip(islands, streams)):
        c = firsts[k]
        if not c.fitness >= reach or not absent_parts(c.R_model, c.position_mm, c.alpha, search.model, search.frame,
                                                      search.rig, parts) > p.max_absent_parts:
            continue  # nan parts (none on hue): no twin
        t = yield from search.turned_steps(c, *TURNED_WINDOWS[1], tilt_deg=ISLAND_TURN_TILT_DEG,
                                           rng=np.random.default_rng(s))
        if t.fitness > c.fitness + p.island_turn_gain:
            firsts[k] = t


def stereo_islands(firsts: list[Candidate], islands: list[tuple[str, PoseSearch]],
                   streams: list[np.random.SeedSequence], left_bgr: np.ndarray, right_bgr: np.ndarray,
                   parts: np.ndarray, p: EstimatorParams) -> Generator[int, None, None]:
    """Each island but the one leading by fitness (`refined` turns that one) whose fit lies within
    `island_turn_within` of the best island's and has its parts in place (at most `max_absent_parts`
    absent, `parts` the model's labels), turned onto the plane both images see under it
    (`PoseSearch.tilt_steps`, its window following the turn), in `firsts` in place, kept when it fits
    better. An island's GA ends on one of the hue fitness' many near-equal peaks (12 random streams of
    renderer 1019's crab island end at 0.71-0.84), and one converged on a creature tilted more than it
    fits leads by nothing: 1019's crab, tilted 38 deg, fitted at 24 (0.755, 7.4 % off) beside a
    look-alike's 0.761; on its plane 0.82-0.84, within 1-3 % of the truth. A fit head-to-tail (its parts
    where the photo has others) would only fit better the wrong way round. The short GAs draw from each
    island's stream in `streams`: where they find nothing better, the acquisition goes on as without
    them. One generation per step."""
    if not p.plane_refine or len(firsts) < 2:
        return
    lead = int(np.argmax([c.fitness for c in firsts]))
    reach = firsts[lead].fitness - p.island_turn_within
    for k, ((_, search), s) in enumerate(zip(islands, streams)):
        c = firsts[k]
        if k == lead or not c.fitness >= reach or not absent_parts(
                c.R_model, c.position_mm, c.alpha, search.model, search.frame, search.rig, parts) <= p.max_absent_parts:
            continue
        t = yield from search.tilt_steps(c, left_bgr, right_bgr, follow=True, rng=np.random.default_rng(s))
        firsts[k] = t if t.fitness > c.fitness else c


def stereo_depth(first: tuple[Detection, Candidate], search: PoseSearch, left_bgr: np.ndarray, right_bgr: np.ndarray,
                 stream: np.random.SeedSequence, looks: dict, p: EstimatorParams,
                 seed: int = 0) -> Generator[int, None, tuple[Detection, Candidate]]:
    """The first candidate, when it passes detection, searched again at the depth both images see under
    it (`stereo_plane.stereo_depth_ratio` r, more than STEREO_DEPTH_MIN and at most STEREO_DEPTH_TOL
    off): slid along its line of sight to r t, alpha / r, re-fitted by a short GA in the twins' window
    (on its own random stream `stream`) and per axis (`aspect_refined`: `at_stereo_depth`); the re-fit
    replaces it when its hue fitness is at most `plane_fitness_tol` below c's (the stereo pair decides
    between fits the hue fitness scores near alike, as for the plane's tilt: `PoseSearch.tilt_steps`) and
    it passes detection too (`looks`: what `detect` reads of the pair), so whether anything is found stays
    as it was. An island's GA ends on one of the hue fitness' many near-equal peaks (12 random streams of
    harbour 1029's island end at 0.69-0.77), and one off in depth is one the two images disagree with:
    1029's fish fitted 6.3 % off (0.749), 7.5 % nearer than both images put it, slid and re-fitted 0.77,
    within 1 %; harbour 1120's squid, fitted 6.6 % off and 41 deg off in tilt (0.741; the truth 0.737),
    re-fitted where both images put it 0.714, 0.4 % off (kept only when fitting better, it stayed off).
    Only on a candidate that passes: a look-alike fitted better at its own depth passes more often
    (harbour null 1573). One generation per step."""
    d, c = first
    if not d.passed:
        return first
    t = yield from at_stereo_depth(search, c, left_bgr, right_bgr, np.random.default_rng(stream), p)
    if t is None or t.fitness < c.fitness - p.plane_fitness_tol:
        return first
    d_t = detect(t, search.model, search.frame, search.rig, search.fit_params, p, seed=seed, **looks)
    return (d_t, t) if d_t.passed else first


def at_stereo_depth(search: PoseSearch, c: Candidate, left_bgr: np.ndarray, right_bgr: np.ndarray,
                    rng: np.random.Generator, p: EstimatorParams, aspect_rng: np.random.Generator | None = None
                    ) -> Generator[int, None, Candidate | None]:
    """`c` searched again at the depth both images see under it (`stereo_plane.stereo_depth_ratio` r, more
    than STEREO_DEPTH_MIN and at most STEREO_DEPTH_TOL off): slid along its line of sight to r t, alpha / r,
    re-fitted by a short GA in the twins' window (random stream `rng`) and per axis (`aspect_refined`, on
    `aspect_rng`; default: the search's stream); None where the two images see it at its depth or say
    nothing (`stereo_depth`, `plane_turned`)."""
    r = stereo_depth_ratio(c.R_model, c.position_mm, c.alpha, search.model, grey(left_bgr), grey(right_bgr),
                           search.rig, on_target=on_target_hue(search.model, search.frame.left))
    if not (np.isfinite(r) and math.log(STEREO_DEPTH_MIN) < abs(math.log(r)) <= math.log(STEREO_DEPTH_TOL)):
        return None
    t = yield from search.local_steps(c.R, r * np.asarray(c.position_mm), c.alpha / r, position_frac=0.03,
                                      heading_deg=15.0, tilt_deg=15.0, alpha_frac=0.08, rng=rng)
    t = yield from aspect_refined(search, dataclasses.replace(t, source=c.source), p, aspect_rng)
    return dataclasses.replace(t, generations=search.ga.generation)


# a candidate whose normal lies more than this (deg) from the stereo plane under it is searched again on the plane
# in a window following the turn (`plane_turned`): the first (the lead island's re-fit on that plane in a narrow
# window vetoed by the hue fitness; `stereo_tilt`), or one failing its parts alone (`parted_turns`)
PLANE_TURN_MIN_DEG = 20.0
# ...and that re-fit is the stereo pair's when the plane re-measured under it lies within this (deg) of its normal
PLANE_AGREE_DEG = 10.0


def stereo_tilt(first: tuple[Detection, Candidate], search: PoseSearch, left_bgr: np.ndarray, right_bgr: np.ndarray,
                looks: dict, p: EstimatorParams, seed: int = 0) -> Generator[int, None, tuple[Detection, Candidate]]:
    """The first candidate, when it passes detection, turned onto the plane both images see under it where it
    contradicts that plane (`plane_turned`); the result replaces it when it passes detection too (`looks`: what
    `detect` reads of the pair), so whether anything is found stays as it was: turned in the leading island's
    refinements (`refined`) instead, a look-alike's fit on a buoy (renderer null 1531, 25 % of its parts absent)
    fitted better on the buoy's plane with fewer parts absent and passed. One generation per step."""
    d, c = first
    if not d.passed:
        return first
    t = yield from plane_turned(search, c, left_bgr, right_bgr, p)
    if t is c:
        return first
    t = dataclasses.replace(t, source=c.source, generations=search.ga.generation)
    d_t = detect(t, search.model, search.frame, search.rig, search.fit_params, p, seed=seed, **looks)
    return (d_t, t) if d_t.passed else first


def plane_turned(search: PoseSearch, c: Candidate, left_bgr: np.ndarray, right_bgr: np.ndarray,
                 p: EstimatorParams, rng: np.random.Generator | None = None) -> Generator[int, None, Candidate]:
    """Where hue bounds the target, a fit whose tilt the stereo plane under it contradicts by more than
    PLANE_TURN_MIN_DEG (for the leading island's, after the hue fitness vetoed its narrow re-fit on that
    plane: `PoseSearch.tilt_steps`, heading and scale held near; `stereo_tilt`'s passing first candidate;
    `parted_turns`' candidate failing its parts alone): turned onto the plane and re-fitted in a
    window that follows the turn (as `stereo_islands`) and per axis (`aspect_refined`), then at the depth
    both images see under the re-fit (`at_stereo_depth`),
    each kept when its hue fitness is at most `plane_fitness_tol` below the fit it replaces, and the whole
    kept only when the stereo pair agrees with the result: the plane re-measured under it within
    PLANE_AGREE_DEG of its normal (a plane measured on glints, foam or a small far creature moves with the
    pose it is measured under; the creature's own does not). The hue fitness alone prefers a wrong tilt on
    some creatures: renderer 1146's fish (tilted 24 deg) fitted 30 deg off at 0.764 (the truth 0.711), 6.3 %
    off, its plane 25 deg from the fit and 6 deg from the truth (re-fitted on it with heading and scale held
    near, 0.66 or less); turned and followed, 0.792, 7 deg and 3.4 % off, its plane re-measured 1.3 deg from
    it. A plane measured on glints beside a small far squid (renderer 1138, 60 deg from the fit, 87 from the
    truth) leaves a re-fit below the tolerance. Own random streams (`Generator.spawn`): where nothing is
    kept, the search goes on as before. Given `rng`, every draw is from children of it, the per-axis
    re-fits' too, and the search's stream is untouched (`parted_turns`: later spawns as without the step);
    else the streams are children of the search's and the per-axis re-fits draw from it. `c` as it is
    otherwise. One generation per step."""
    if not p.plane_refine or not np.isfinite(c.fitness):
        return c
    on_target = on_target_hue(search.model, search.frame.left)
    gl, gr = grey(left_bgr), grey(right_bgr)
    plane = fit_target_plane(c.R, c.position_mm, c.alpha, search.model, gl, gr, search.rig, on_target=on_target)
    if plane is None or _off_plane_deg(c, plane) <= PLANE_TURN_MIN_DEG:
        return c
    if rng is None:  # own streams: where nothing is kept, the search goes on as before
        (turn_rng, depth_rng), aspect_rngs = search.ga.rng.spawn(2), (None, None)
    else:  # every draw from `rng`'s children: the search's stream untouched
        turn_rng, depth_rng, *aspect_rngs = rng.spawn(4)
    t = yield from search.tilt_steps(c, left_bgr, right_bgr, follow=True, rng=turn_rng)
    if t is c:
        return c
    t = yield from aspect_refined(search, t, p, aspect_rngs[0])
    d = yield from at_stereo_depth(search, t, left_bgr, right_bgr, depth_rng, p, aspect_rngs[1])
    if d is not None and d.fitness >= t.fitness - p.plane_fitness_tol:
        t = d
    if t.fitness < c.fitness - p.plane_fitness_tol:
        return c
    plane = fit_target_plane(t.R, t.position_mm, t.alpha, search.model, gl, gr, search.rig, on_target=on_target)
    return t if plane is not None and _off_plane_deg(t, plane) <= PLANE_AGREE_DEG else c


# the answer is turned onto the plane measured with the right image's scale taken out (`scaled_plane`) when that
# plane lies within this (deg) of its normal: beyond it, the plane is another surface's (glints: renderer 1138)
SCALED_PLANE_MAX_DEG = PLANE_TURN_MIN_DEG


def scaled_plane(first: tuple[Detection, Candidate], search: PoseSearch, left_bgr: np.ndarray, right_bgr: np.ndarray,
                 p: EstimatorParams) -> tuple[Detection, Candidate]:
    """The answer, when it passes detection, turned onto the plane both images see under it measured with the
    right image's scale against the left taken out (`stereo_plane.fit_target_plane(scale=True)`, `_scale_shift`),
    at its place (no re-fit: its depth, heading and size stay), when that plane lies within SCALED_PLANE_MAX_DEG of
    its normal and the hue fitness there is at most `plane_fitness_tol` below. The fit sits on the plane measured
    with the written rig (`PoseSearch.tilt_steps`), and a focal length 0.5 % off in each camera (the benchmarks'
    calibration error; opposite signs in half the scenes) tips that plane by 5-13 degrees at 1-1.4 m; taken out,
    the plane at the truth pose lies 2.35 degrees (median, held-out 1 renderer same-photo scenes) from the
    creature's against 3.30, the rig that rendered them 2.35. Re-fitted on it instead (the plane step and the
    islands' turns on the scaled plane), the tilt medians fell as far but the same-photo depth rose (tuned renderer
    0.87 -> 1.04 %, better in 10 of 30): the hue fitness, projecting with the written rig, puts the depth
    elsewhere at the right tilt. Detection is not run again: found or not stays as it was. No random draws."""
    d, c = first
    if not d.passed or not np.isfinite(c.fitness):
        return first
    plane = fit_target_plane(c.R, c.position_mm, c.alpha, search.model, grey(left_bgr), grey(right_bgr), search.rig,
                             on_target=on_target_hue(search.model, search.frame.left), scale=True)
    if plane is None or _off_plane_deg(c, plane) > SCALED_PLANE_MAX_DEG:
        return first
    R, _ = align_to_plane(c.R, c.position_mm, plane)
    t = dataclasses.replace(c, R=R)
    f = float(fitness(t.R_model[None], np.asarray(t.position_mm)[None], np.array([t.alpha]), search.model, search.frame,
                      search.rig, search.fit_params)[0])
    return (d, dataclasses.replace(t, fitness=f)) if f >= c.fitness - p.plane_fitness_tol else first


def _off_plane_deg(c: Candidate, plane: PlaneFit) -> float:
    """The angle (deg) between the candidate's model normal and the plane's (either side)."""
    return math.degrees(math.acos(min(1.0, abs(float(np.asarray(c.R)[:, 2] @ plane.normal)))))


# a first candidate whose depth lies more than this factor from where both images put the surface under it is
# searched again there (`stereo_depth`): more than one step of `stereo_depth_ratio`'s grid (2.9 %); at the truth
# pose the ratio is 1 or one step off in 59 of 60 scenes (the first 30 of each generator), two steps in renderer 1004
STEREO_DEPTH_MIN = 1.03


def refined(search: PoseSearch, c: Candidate, frame: StereoHue, left_bgr: np.ndarray, right_bgr: np.ndarray,
            p: EstimatorParams, settle: bool = True) -> Generator[int, None, Candidate]:
    """The leading island's refinements, one generation per step: where the contour rule scores, the
    grown fits (`PoseSearch.grown_steps`: its narrow peak), its turns shrunk (`shrunk_turns`) and its
    quarter turns (`quarter_twins`); the look-alike twins (mirror, heading + 180 deg); the tilt from the
    stereo plane; the per-axis size; where the contour rule scores, the depth both
    images see under the fit (`stereo_plane.onto_surface`), and with `settle`: where that slide went beyond
    STEREO_DEPTH_TOL, the ladder and the slide once more; then, after the slide whether it went far or not, the
    fit re-fitted with the body's grey layout beside the fitness (`layout_refit`)."""
    if frame.chroma is not None and p.contour_grow > 1.0:
        c = yield from contour_ladder(search, c, p)
    c = yield from search.twin_steps(c)
    if p.plane_refine and np.isfinite(c.fitness):
        c = yield from search.tilt_steps(c, left_bgr, right_bgr)
    c = yield from aspect_refined(search, c, p)
    if frame.chroma is not None and np.isfinite(c.fitness):  # hues everywhere: the depth both images see under it
        slid = onto_surface(c, search, left_bgr, right_bgr, p.plane_fitness_tol)
        if settle and p.contour_grow > 1.0 and slid_far(c, slid):
            # slid from a pose pairing two surfaces: its size and heading were judged at the wrong depth, so
            # the ladder again at the depth both images see, and the slide again (the motorcycle's crate cut
            # from the right image seed 43: refined at 2.27 m, 39 % too near, slid to 3.71 m at 0.741, 20 %
            # small, behind an unrefined island's 0.806 at 16.5 %; settled again 0.847 at 2.4 %)
            slid = yield from contour_ladder(search, slid, p)
            slid = onto_surface(slid, search, left_bgr, right_bgr, p.plane_fitness_tol)
        c = slid
        if settle:
            # the body's grey layout beside the fitness: the fitness alone prefers fits 15-19 % off in size on the
            # real pair (the tank at 0.6x seed 5, 15.9 % small: layout 0.42 against the truth's 0.68; re-fitted 1.0 %)
            c = yield from layout_refit(search, c, stereo_grey(left_bgr, right_bgr))
    return c


# the layout re-fit (`layout_refit`): the weight of the appearance beside the fitness in its objective, its
# window's alpha (+- fraction), and its stream's key under the search's seed sequence (far above any count
# `Generator.spawn` reaches: every other draw is as before)
LAYOUT_WEIGHT = 0.25
LAYOUT_ALPHA_FRAC = 0.3
LAYOUT_STREAM = 0x1A70
# the rise of the layout (a correlation, -1..1) a re-fit must bring to replace the fit: where it moves less, the
# objective's rise is the fitness' own, which the full search already weighed (the motorcycle's crate from the
# left image seed 20: layout -0.15 -> -0.13, fitness 0.757 -> 0.840, 1.3 -> 18.6 % in size; the tank at 0.6x seed
# 5, 0.42 -> 0.59, 15.9 -> 1.0 %; the crate from the right image seed 47, 0.49 -> 0.70, 16.4 -> 14.6 %). A photo
# of n inner points whose correlation's noise (~1/sqrt(n)) reaches that rise (n <= 100: the motorcycle's fender
# and crate at 0.6x, 81 and 89 points) is not re-fitted: there the layout chose fits 7-20 % off (the fender at
# 0.6x seed 19: 0.24 -> 0.55, 12.0 -> 20.9 % in size; seed 32 0.7 -> 14.8 %)
LAYOUT_RISE = 0.1


def layout_noisy(model: PhotoModel) -> bool:
    """The photo's grey layout is too noisy for `layout_refit`: a correlation over n inner points varies by
    ~1/sqrt(n), which reaches LAYOUT_RISE at n <= 1 / LAYOUT_RISE^2 (100 points). n is all of the model's
    inner points (`PhotoModel.inner_uv`): `appearance.appearance` correlates only those landing on a target
    hue in each camera, fewer, so the bound is the lenient one."""
    return len(model.inner_uv) * LAYOUT_RISE ** 2 <= 1.0


class _LayoutSearch(PoseSearch):
    """A PoseSearch whose objective is the fitness plus LAYOUT_WEIGHT x the appearance (`appearance.appearance`:
    the body's grey layout against the photo's; -1 where no camera has enough inner points on target hue)."""

    grey_frame: StereoGrey

    def _fitness(self, g: np.ndarray) -> np.ndarray:
        R, t, alpha, valid = self.space.decode(g)
        f = np.full(len(g), -np.inf)
        for i in np.flatnonzero(valid):
            F = fitness(R[i], t[i], alpha[i], self.model, self.frame, self.rig, self.fit_params)[0]
            A = appearance(R[i], t[i], alpha[i], self.model, self.frame, self.grey_frame, self.rig)
            f[i] = F + LAYOUT_WEIGHT * (A if np.isfinite(A) else -1.0)
        return f


def layout_refit(search: PoseSearch, c: Candidate, grey_frame: StereoGrey) -> Generator[int, None, Candidate]:
    """Where the contour rule scores, after the slide: a short GA of its own (half the patience; position +- 3 %
    of the depth, heading +- 20 deg, tilt +- 30 deg, alpha +- LAYOUT_ALPHA_FRAC) around `c`, seeded with it, whose
    objective is the fitness plus LAYOUT_WEIGHT x the body's grey layout against the photo's
    (`appearance.appearance`, the correlation `appearance_twin` uses; it normalises on the image); its best
    replaces `c` when that objective rises by more than a point of fitness (`point_weight`), with its plain
    fitness. On the real pair the fitness alone scores fits 15-19 % off in size above the truth (the inner
    points all match on a smaller fit; only the outline says where the target ends, and a crop or an occluder
    blurs that): their layouts read -0.35 to 0.49 against their truths' 0.46-0.81, met answers 0.55-0.69.
    Only where the layout itself rises by more than LAYOUT_RISE (else the rise is the fitness' own), and not on a
    photo whose layout is too noisy to tell such a rise (`layout_noisy`: no draw there, so its estimate is as
    without the re-fit). The re-fit's GA is at aspect 1 (seeded with `c`'s R, position and alpha; the per-axis
    size `aspect_refined` gave `c` is not carried): it replaces `c` only when, at aspect 1, it beats `c` as
    scored at `c`'s own aspect, and the replacement has aspect 1."""
    if not np.isfinite(c.fitness) or layout_noisy(search.model):
        return c
    p = search.est_params
    short = dataclasses.replace(p, min_generations=max(1, p.patience // 2), patience=max(2, p.patience // 2),
                                max_generations=max(p.patience, p.max_generations // 4))
    seq = search.ga.rng.bit_generator.seed_seq
    rng = np.random.default_rng(np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, LAYOUT_STREAM)))
    sub = _LayoutSearch(search.model, search.rig, search.frame, search.ga.params, short, search.fit_params, rng)
    sub.grey_frame = grey_frame
    z = float(c.position_mm[2])
    sub.ga.reset(sub.space.window(c.R, c.position_mm, c.alpha, position_mm=0.03 * z, heading_deg=20.0, tilt_deg=30.0,
                                  alpha_frac=LAYOUT_ALPHA_FRAC))
    sub.seed(c.R, c.position_mm, c.alpha)
    k = yield from sub.steps()
    search.ga.evaluations += sub.ga.evaluations
    search.ga.generation += k.generations
    a0 = appearance(c.R_model, c.position_mm, c.alpha, search.model, search.frame, grey_frame, search.rig)
    before = c.fitness + LAYOUT_WEIGHT * (a0 if np.isfinite(a0) else -1.0)
    if k.fitness <= before + point_weight(search.model, search.fit_params):
        return c
    F = float(fitness(k.R, k.position_mm, k.alpha, search.model, search.frame, search.rig, search.fit_params)[0])
    if F < c.fitness:  # the layout chooses among fits the fitness holds at least as good, never against it
        return c
    a1 = appearance(k.R_model, k.position_mm, k.alpha, search.model, search.frame, grey_frame, search.rig)
    if (a1 if np.isfinite(a1) else -1.0) - (a0 if np.isfinite(a0) else -1.0) <= LAYOUT_RISE:
        return c  # the layout did not choose: a fitter fit alone is a second GA's draw on the fitness' own peak
    return dataclasses.replace(k, fitness=F, source=c.source)


def slid_far(c: Candidate, slid: Candidate) -> bool:
    """`slid` (`stereo_plane.onto_surface` of `c`) lies more than STEREO_DEPTH_TOL off `c`'s depth: `c`
    paired two surfaces."""
    return slid is not c and abs(math.log(slid.position_mm[2] / c.position_mm[2])) > math.log(STEREO_DEPTH_TOL)


def contour_ladder(search: PoseSearch, c: Candidate, p: EstimatorParams) -> Generator[int, None, Candidate]:
    """Where the contour rule scores: `c` refined in place and grown (`PoseSearch.grown_steps`: its narrow
    peak), its turns shrunk (`shrunk_turns`), its quarter turns (`quarter_twins`); one generation per step."""
    # a grown fit must win by more than the fitness' resolution: on a small photo-model (the real pair's
    # crate at 0.6x, 115 points) fits 12-30 % too large score alike within a point of the narrow peak
    gain = point_weight(search.model, search.fit_params)
    c = yield from search.grown_steps(c, (1.0, math.sqrt(p.contour_grow), p.contour_grow), min_gain=gain)
    c = yield from shrunk_turns(search, c, math.sqrt(p.contour_grow), gain)
    return (yield from quarter_twins(search, c, gain))


# the quarter twins' short GA (`quarter_twins`): tilt within +- this (deg); position +- 3 % of the depth, heading
# +- 15 deg and alpha +- 8 % as the grown fits'
QUARTER_TILT_DEG = 30.0


def quarter_twins(search: PoseSearch, c: Candidate, min_gain: float) -> Generator[int, None, Candidate]:
    """`c` or its fit turned a quarter either way about the photo mask's centroid (`twins.turned_about_centroid`,
    quarters +-1) and scaled about its origin by the photo's elongation e = long / short side of its box
    (alpha / f, f = e and 1 / e: the turned model's long side where the fit's short side lay, or its short
    side where the long one lay), each refined by a short GA (tilt within +- QUARTER_TILT_DEG); the best
    when it scores more than `min_gain` higher. Where the contour rule scores, an oblong target inside a
    region of hues it shares (the real pair's crate, 99 x 76 px cut from the right image, on the shelf's
    wood and cardboard) has a broad ridge of fits turned 90 degrees and shrunk until the model's long
    side spans the target's short one, below the narrow peak at its heading and size, and growing keeps
    the heading: seed 4's island ends there (0.839, turned 96 degrees, 25 % small); turned back and grown
    by e = 1.30 its short GAs end at 0.85-0.91, 0-8 % off (6 of 6 random streams). A square photo (e ~ 1)
    is tried turned a quarter at its size. Grown and shrunk by 1.2 instead of e, the twins found higher
    fits 13-23 % off on the square photos (3 of 108 runs lost). Own random streams (`Generator.spawn`):
    the search's stream is as before. One generation per step."""
    if not np.isfinite(c.fitness):
        return c
    best = c
    e = max(search.model.size_px) / min(search.model.size_px)
    tries = [(q, f) for q in (1, -1) for f in (e, 1.0 / e)]
    for (quarters, f), rng in zip(tries, search.ga.rng.spawn(len(tries))):
        R, t = turned_about_centroid(c.R, c.position_mm, c.alpha, search.model, c.aspect, quarters)
        k = yield from search.local_steps(R, t, c.alpha / f, position_frac=0.03, heading_deg=15.0,
                                          tilt_deg=QUARTER_TILT_DEG, alpha_frac=0.08, rng=rng)
        if k.fitness > max(best.fitness, c.fitness + min_gain):
            best = k
    return dataclasses.replace(best, source=c.source) if best is not c else c


def shrunk_turns(search: PoseSearch, c: Candidate, f: float, min_gain: float) -> Generator[int, None, Candidate]:
    """`c` or its fit turned a half turn, and for a near-square photo (its box's long over short side
    e < f) a quarter turn either way, about the photo mask's centroid (`twins.turned_about_centroid`),
    each as it is and mirrored about the line of sight (`twins.reflected_rotation`), shrunk about its
    origin by `f` (alpha · f; the estimator's f = sqrt(`contour_grow`), the grown fits' first factor) and
    refined by a short GA as the quarter twins are; the best when it scores more than `min_gain` higher.
    Where the contour rule scores, the islands on a near-square photo (the real pair's crate cut from
    the left image, e = 1.01, and at 0.6x) can end turned 90-180 degrees and grown past the target
    (18-34 % too large, 0.77-0.87 against the truth's 0.89: 5 of 18 seeds of the crate from the left
    image), a ridge the grown fits (larger only) and the quarter twins (scaled by e ~ 1: at its size)
    cannot leave. An oblong photo's quarter turns are the quarter twins' (scaled by e): shrunk by f
    as well they went back onto the ridge those leave (the crate cut from the right image, e = 1.30,
    seed 16: 3.7 -> 21.5 %). Shrunk in place (no turn) the tank's and fender's fits went onto the
    ridge inside them (tank left seed 3 3.3 -> 13.1 %, fender left seed 16 1.0 -> 14.4 %); turned and
    grown by f, onto fits past the target tilted 45-52 degrees (the crate at 0.6x seed 5 14.0 ->
    35.7 %). Tried before the quarter twins: those can turn such a fit to the target's heading at its
    grown size (crate left seeds 17, 18: +24-37 %), where only an unturned shrink would reach the peak.
    Own random streams (`Generator.spawn`, one per turn whether tried or not): the search's stream is
    as before. One generation per step."""
    if not np.isfinite(c.fitness):
        return c
    best = c
    e = max(search.model.size_px) / min(search.model.size_px)
    tries = []
    for quarters in (1, -1, 2):
        R, t = turned_about_centroid(c.R, c.position_mm, c.alpha, search.model, c.aspect, quarters)
        tries += [(quarters, R, t), (quarters, reflected_rotation(R, t), t)]
    for (quarters, R, t), rng in zip(tries, search.ga.rng.spawn(len(tries))):
        if quarters != 2 and e >= f:
            continue  # an oblong photo's quarter turns are the quarter twins' (scaled by e)
        k = yield from search.local_steps(R, t, c.alpha * f, position_frac=0.03, heading_deg=15.0,
                                          tilt_deg=QUARTER_TILT_DEG, alpha_frac=0.08, rng=rng)
        if k.fitness > max(best.fitness, c.fitness + min_gain):
            best = k
    return dataclasses.replace(best, source=c.source) if best is not c else c


def aspect_refined(search: PoseSearch, c: Candidate, p: EstimatorParams, rng: np.random.Generator | None = None
                   ) -> Generator[int, None, Candidate]:
    """`c` re-fitted per photo axis (`PoseSearch.refine_aspect`, alpha_x / alpha_y within a factor
    `aspect_max`; random stream `rng`, default the search's), kept when it fits at least `aspect_min_gain`
    better; one step (its generations). `c` as it is when the per-axis size is off or c has no fitness."""
    if p.aspect_max > 1.0 and np.isfinite(c.fitness):
        g0 = search.ga.generation
        k = search.refine_aspect(c, p.aspect_max, rng)
        if k.fitness >= c.fitness + p.aspect_min_gain:
            c = k
        yield search.ga.generation - g0
    return c


# each island's turned twin (`acquisition`; kept when it fits `island_turn_gain` better): its tilt window (deg)
ISLAND_TURN_TILT_DEG = 30.0

# the head-to-tail twin's refinement windows (`PoseSearch.turned_steps`), tried in turn until one
# wins: (position +- this fraction of the depth, alpha within a factor 1 +- this). A fit displaced
# along the body has its twin's centroid off the creature's, and the hue fitness of a creature cut
# by foam has more than one peak along it: the wider window finds the twin there. The wider window
# is listed twice on purpose: the second entry is a fresh short GA (new random population) in the
# same window, a second chance where the first run settled on the wrong peak.
TURNED_WINDOWS = ((0.03, 0.08), (0.06, 0.15), (0.06, 0.15))


def appearance_twin(first: tuple[Detection, Candidate], search: PoseSearch, grey_frame: StereoGrey,
                    p: EstimatorParams, seed: int = 0, value_frame: StereoGrey | None = None,
                    parts: np.ndarray | None = None, chroma: StereoChroma | None = None,
                    weight: np.ndarray | None = None, foam: StereoHue | None = None,
                    cells: StereoCells | None = None, saturation_frame: StereoGrey | None = None
                    ) -> Generator[int, None, tuple[Detection, Candidate]]:
    """The chosen candidate or its head-to-tail twin at the same place (`PoseSearch.turned_steps`:
    turned about the photo mask's centroid, refined by a short GA in each of TURNED_WINDOWS in
    turn), decided by the appearance cue (`vision/appearance.py`): the hue fitness scores a
    creature of one hue and its turned twin alike, the photo's brightness layout does not. A twin
    is taken when its fitness is at most `twin_fitness_tol` below the candidate's, its appearance
    score at least `twin_min_appearance` and `twin_appearance_margin` above the candidate's, and
    it passes detection whenever the candidate does (it is then re-fitted per axis as the leading
    island is). A candidate whose own score leaves no room for that (>= min + margin) is kept
    without a search. `value_frame` (`appearance.stereo_value`): the twin's detection may excuse an
    outline spill as the candidate's may (vision/detection.py); `parts` (the model's
    `parts.model_parts`), `chroma` (the pair's a*b* planes), `weight` (their hues' distinctive
    weight), `foam` (the hue the parts check reads, `parts.foam_marked`), `cells` and `saturation_frame`
    (`appearance.stereo_saturation`): as the candidate's detection had them. One generation per step;
    returns (detection, candidate)."""
    d, c = first
    model, frame, rig = search.model, search.frame, search.rig

    def score(x: Candidate) -> float:
        return appearance(x.R_model, x.position_mm, x.alpha, model, frame, grey_frame, rig)

    a_c = d.appearance if np.isfinite(d.appearance) else score(c)  # detect measured it with these frames
    if not np.isfinite(a_c) or a_c >= p.twin_min_appearance + p.twin_appearance_margin:
        return first
    for position_frac, alpha_frac in TURNED_WINDOWS:
        twin = yield from search.turned_steps(c, position_frac, alpha_frac)
        a_t = score(twin) if twin.fitness >= c.fitness - p.twin_fitness_tol else math.nan
        if a_t >= p.twin_min_appearance and a_t - a_c >= p.twin_appearance_margin:
            break
    else:
        return first
    twin = yield from aspect_refined(search, twin, p)
    d_t = detect(twin, model, frame, rig, search.fit_params, p, seed=seed, grey_frame=grey_frame,
                 value_frame=value_frame, parts=parts, chroma=chroma, weight=weight, foam=foam, cells=cells,
                 saturation_frame=saturation_frame)
    if d.passed and not d_t.passed:
        return first
    return d_t, twin


# a grown fit replaces its candidate when its outline spills at most this share of the candidate's
# (`grown_outlines`): a fit shrunk inside the creature spills where the creature goes on past its
# outline, and grown to the creature's size that spill goes with it; where the model lies on
# something of another shape, the spill stays where the shapes differ
GROWN_SPILL_RATIO = 0.5


def grown_outlines(results: list[tuple[Detection, Candidate]], searches: dict[str, PoseSearch], looks: dict,
                   p: EstimatorParams, seed: int = 0) -> Generator[int, None, list[tuple[Detection, Candidate]]]:
    """The candidates, re-ranked after each one that fails its outline test alone (its contrast
    and its parts pass) was tried grown: scaled about its origin by sqrt(`outline_grow`) and by
    `outline_grow` (alpha / f), each from the candidate and refined by a short GA in a window of
    alpha +- 8 % (`PoseSearch.grown_steps`); the fittest of them, when the hue fitness rose. An
    island's GA can end on a fit shrunk inside the creature (harbour 1056: a fish whose highlights
    carry no hue, 0.742 at 1.25 x the truth's alpha), whose outer points land on the creature
    itself. The grown fit replaces the candidate when it passes detection and its outline spills
    at most GROWN_SPILL_RATIO of the candidate's spill. `searches`: the islands by name (the
    candidates' sources); `looks`: what `detect` reads of the pair. One generation per step."""
    out = list(results)
    for k, (d, c) in enumerate(results):
        if d.passed or d.contrast < p.min_contrast or d.absent_parts > p.max_absent_parts:
            continue  # passes, or fails on more than its outline (nan parts: none on hue, not a reason)
        search, grown = searches[c.source], c
        for f in (math.sqrt(p.outline_grow), p.outline_grow):
            g = yield from search.grown_steps(c, (f,))
            grown = g if g.fitness > grown.fitness else grown
        if grown is c:
            continue
        d_g = detect(grown, search.model, search.frame, search.rig, search.fit_params, p, seed=seed, **looks)
        if d_g.passed and d_g.outer_on_target <= GROWN_SPILL_RATIO * d.outer_on_target:
            out[k] = (d_g, grown)
    return ranked(out, p.passed_standing_ratio)


# the turns `parted_turns` re-fits a candidate failing on its parts alone at (quarter turns about the photo
# mask's centroid), each by a short GA with heading +- PARTED_HEADING_DEG (the four cover every heading),
# tilt +- QUARTER_TILT_DEG, position +- 3 % of the depth and alpha +- 8 %
PARTED_QUARTERS = (0, 1, -1, 2)
PARTED_HEADING_DEG = 45.0
# the spawn key of `parted_turns`' plane step's random streams (candidate k's: a child of (this, k) of the
# estimate's seed): no spawn of the acquisition's reaches it (estimator.BRIDGED_STREAMS is 1 << 20)
PARTED_PLANE_STREAMS = 1 << 21


def parted_turns(results: list[tuple[Detection, Candidate]], searches: dict[str, PoseSearch], looks: dict,
                 p: EstimatorParams, seed: int = 0, left_bgr: np.ndarray | None = None,
                 right_bgr: np.ndarray | None = None) -> Generator[int, None, list[tuple[Detection, Candidate]]]:
    """The candidates, re-ranked after each one that fails its parts alone (`Detection.fails_on_parts`:
    its contrast and its outline pass, the outline judged and not on another object, its body off the
    water; more than `max_absent_parts` of its parts absent, or two absent and one on bare water) was
    re-fitted turned: at each of PARTED_QUARTERS quarter turns about the photo mask's centroid
    (`twins.turned_about_centroid`), by a short GA (PARTED_HEADING_DEG); the fittest of
    them, when the hue fitness rose, replaces the candidate when it passes detection. An island's
    GA can end at the creature's place with its heading off (harbour 1208, a crab tilted 38 deg:
    heading 31 deg off, 0.703 against the truth's 0.838; 1238, a quarter turn off), where the
    model's legs lie beside the creature's and detection finds them absent; the decision stays
    detection's, on the re-fit. Where no turn's re-fit replaces the candidate and hue bounds the target,
    the candidate turned onto the plane both images see under it (`plane_turned`, given the pair
    `left_bgr`, `right_bgr`) replaces it when it fits better and passes: an island's GA can end at the
    creature's place tilted off it by more than the turns' tilt window (harbour 2744, a crab of the same
    photo tilted 38 deg: fitted at 11, 43 deg off its plane, 0.806 with 3 parts absent; on the plane
    0.959, 0.26 % off). Own random streams (`Generator.spawn`, one per turn whether tried or not): the
    search's stream is as before; the plane step's are fixed (candidate k's from the spawn key
    (PARTED_PLANE_STREAMS, k) of `seed`), so that where it replaces nothing the later steps (`grown_turns`,
    `stereo_tilt`) draw as without it. `searches`, `looks`: as `grown_outlines`'. One generation per step."""
    out = list(results)
    for k, (d, c) in enumerate(results):
        if not d.fails_on_parts or not np.isfinite(c.fitness):
            continue  # passes, or fails on more than its parts
        search, best = searches[c.source], c
        for quarters, rng in zip(PARTED_QUARTERS, search.ga.rng.spawn(len(PARTED_QUARTERS))):
            R, t = ((c.R, c.position_mm) if quarters == 0
                    else turned_about_centroid(c.R, c.position_mm, c.alpha, search.model, c.aspect, quarters))
            g = yield from search.local_steps(R, t, c.alpha, position_frac=0.03, heading_deg=PARTED_HEADING_DEG,
                                              tilt_deg=QUARTER_TILT_DEG, alpha_frac=0.08, rng=rng)
            best = g if g.fitness > best.fitness else best
        if best is not c:
            best = dataclasses.replace(best, source=c.source)
            d_b = detect(best, search.model, search.frame, search.rig, search.fit_params, p, seed=seed, **looks)
            if d_b.passed:
                out[k] = (d_b, best)
                continue
        if left_bgr is None or right_bgr is None or search.frame.chroma is not None:
            continue  # the contour regime: the stereo plane is not this step's
        plane_rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(PARTED_PLANE_STREAMS, k)))
        turned = yield from plane_turned(search, c, left_bgr, right_bgr, p, plane_rng)
        if turned is c or not turned.fitness > c.fitness:
            continue
        turned = dataclasses.replace(turned, source=c.source, generations=search.ga.generation)
        d_t = detect(turned, search.model, search.frame, search.rig, search.fit_params, p, seed=seed, **looks)
        if d_t.passed:
            out[k] = (d_t, turned)
    return ranked(out, p.passed_standing_ratio)


# `grown_turns` re-fits a fit shrunk inside the creature at each of PARTED_QUARTERS quarter turns about the
# photo mask's centroid and grown about it by each of sqrt(`outline_grow`) and `outline_grow`, by short GAs
# (heading +- PARTED_HEADING_DEG, tilt +- QUARTER_TILT_DEG, position +- 3 % of the depth, alpha +- 8 %)


def grown_about_centroid(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, f: float,
                         aspect: float = 1.0) -> tuple[np.ndarray, float]:
    """A pose's model grown f times about the photo mask's centroid (`twins.mask_centroid_mm`), the
    centroid staying put: alpha' = alpha / f (px/mm) and t' = t + M (c - c'), M = R · diag(k, 1/k, 1),
    c and c' = f c the centroid (mm, model frame) at alpha and alpha'. R (3, 3) the rotation, t (3,) mm
    in the left camera frame. Returns (t', alpha').

    >>> from types import SimpleNamespace
    >>> m = SimpleNamespace(mask=np.pad(np.ones((2, 4), np.uint8), ((0, 0), (0, 4))), origin_px=(0.0, 0.0))
    >>> t2, a2 = grown_about_centroid(np.eye(3), np.zeros(3), 1.0, m, 2.0)
    >>> c = mask_centroid_mm(m, 1.0); bool(np.allclose(mask_centroid_mm(m, a2) + t2, c)), a2
    (True, 0.5)
    """
    k = np.array([aspect, 1.0 / aspect, 0.0])
    c = mask_centroid_mm(model, alpha) * k
    return np.asarray(t, dtype=np.float64) + np.asarray(R, dtype=np.float64) @ (c - f * c), alpha / f


def foam_neutral(search: PoseSearch, foam: StereoHue | None,
                 w: float) -> Callable[[Candidate], tuple[float, np.ndarray]]:
    """A fit's hue fitness with its inner points on foam (`foam`: the pair's hue with its foam marked,
    `parts.foam_marked`) counted as matches, `w` (`fitness.point_weight`) each, the cameras' mean, and the
    share of its inner points on foam in each camera ((2,), `parts.foam_share_inner`); the fitness as it
    is and no share without `foam` and where the contour rule bounds the target. The fitness scores a pixel
    without hue 0, so that no hue cannot raise a score; but where a band of foam crosses the creature, a
    fit on one of its pieces scores above the creature's whole pose, whose points the band hides (renderer
    2727: a fish 0.62 x its size on its tail half, 0.625 against the truth's 0.608; counted so, 0.671
    against 0.752). Returns a function of the candidate: (score, shares)."""
    n_in = len(search.model.inner_uv)

    def score(g: Candidate) -> tuple[float, np.ndarray]:
        if foam is None or search.frame.chroma is not None or not np.isfinite(g.fitness):
            return g.fitness, np.zeros(2)
        share = foam_share_inner(g.R_model, g.position_mm, g.alpha, search.model, foam, search.rig)
        return g.fitness + w * n_in * float(np.mean(share)), share
    return score


def grown_turns(results: list[tuple[Detection, Candidate]], searches: dict[str, PoseSearch], looks: dict,
                p: EstimatorParams, seed: int = 0) -> Generator[int, None, list[tuple[Detection, Candidate]]]:
    """The candidates, re-ranked after each one whose outline spills (its contrast passes, its outline
    does not, judged and not on another object: vision/detection.py), whatever its parts say, was
    re-fitted turned and grown: at each of PARTED_QUARTERS quarter turns about the photo mask's centroid
    (`twins.turned_about_centroid`) and grown about it (`grown_about_centroid`) by sqrt(`outline_grow`)
    and `outline_grow`, each by a short GA (heading +- PARTED_HEADING_DEG). Of the re-fits that fit the
    pair as well as the candidate to within the fitness' resolution (`fitness.point_weight`), the
    fittest that passes detection with its outline spilling at most GROWN_SPILL_RATIO of the
    candidate's spill (as `grown_outlines`') replaces it. An island's GA can end on a fit shrunk
    inside the creature AND turned on it (renderer 1406, 1240, 2138: 21-31 % too small, turned
    20-92 degrees, its outer points on the creature and its parts beside the creature's), below the
    truth's fitness; growing alone keeps the heading (`grown_outlines`), turning alone the size
    (`parted_turns`). In 2138 the re-fit turned back a quarter and grown 1.35 x passes at 0.7005
    against the candidate's 0.7009, the fittest re-fit (0.715, unturned) does not. When no candidate's
    re-fit is chosen so, the re-fits lying under foam (at least `foam_part_share` of their inner points on
    it in each camera, `parts.under_foam`'s level) are weighed again with their inner points on foam
    counted as matches (`foam_neutral`), the candidate's too: a fit on one piece of a foam-split creature
    outscores the whole creature, whose points under the band score 0 (renderer 2727). Own random streams
    (`Generator.spawn`, one per try whether it runs or not): the search's stream is as before. `searches`,
    `looks`: as `grown_outlines`'. One generation per step."""
    out, tried = list(results), []
    for k, (d, c) in enumerate(results):
        if (d.passed or d.contrast < p.min_contrast or not d.outer_on_target > p.max_outer_on_target
                or d.outline_judged < MIN_JUDGED_SHARE or d.off_water > MAX_OFF_WATER or not np.isfinite(c.fitness)):
            continue  # passes, fails its contrast, or its outline does not spill (nan cues: not a reason)
        search, fits = searches[c.source], []
        tries = [(q, f) for q in PARTED_QUARTERS for f in (math.sqrt(p.outline_grow), p.outline_grow)]
        for (quarters, f), rng in zip(tries, search.ga.rng.spawn(len(tries))):
            R, t = turned_about_centroid(c.R, c.position_mm, c.alpha, search.model, c.aspect, quarters)
            t, alpha = grown_about_centroid(R, t, c.alpha, search.model, f, c.aspect)
            g = yield from search.local_steps(R, t, alpha, position_frac=0.03, heading_deg=PARTED_HEADING_DEG,
                                              tilt_deg=QUARTER_TILT_DEG, alpha_frac=0.08, rng=rng)
            fits.append(dataclasses.replace(g, source=c.source))
        # the fittest re-fit that passes, among those fitting as well as the candidate to within the
        # fitness' resolution (one point's weight: `fitness.point_weight`)
        w = point_weight(search.model, search.fit_params)
        tried.append((k, w, fits))
        chosen = _first_passing([g for g in sorted(fits, key=lambda g: -g.fitness) if g.fitness >= c.fitness - w],
                                d, search, looks, p, seed)
        if chosen is not None:
            out[k] = chosen
    # when no candidate's re-fit was chosen so: among the others, those lying under foam (`parts.under_foam`: at
    # least foam_part_share of their inner points on it in each camera, a band across them) that fit as well
    # with each fit's inner points on foam counted as matches, the candidate's too (`foam_neutral`), fittest so
    # counted first
    for k, w, fits in tried if all(out[k] is results[k] for k, _, _ in tried) else ():
        (d, c), search = results[k], searches[results[k][1].source]
        score = foam_neutral(search, looks.get("foam"), w)
        bar = score(c)[0] - w
        counted = sorted(((score(g), g) for g in fits if not g.fitness >= c.fitness - w), key=lambda sg: -sg[0][0])
        chosen = _first_passing([g for (f, share), g in counted if f >= bar and shares_under_foam(share, p.foam_part_share)],
                                d, search, looks, p, seed)
        if chosen is not None:
            out[k] = chosen
    return ranked(out, p.passed_standing_ratio)


# the spawn key of `foam_turns`' random streams: a child of the seed that the acquisition's own spawns (a few
# dozen) never reach, nor the bridged or grown islands' (estimator.BRIDGED_STREAMS, 1 << 20)
FOAM_TURN_STREAMS = (1 << 20) + 1


def foam_turns(results: list[tuple[Detection, Candidate]], searches: dict[str, PoseSearch], looks: dict,
               p: EstimatorParams, seed: int = 0) -> Generator[int, None, list[tuple[Detection, Candidate]]]:
    """The candidates, re-ranked after each one that fails its parts alone (`Detection.fails_on_parts`)
    was re-fitted at each of PARTED_QUARTERS quarter turns about the photo mask's centroid by a short
    GA (as `parted_turns`') whose objective counts the inner points on foam as matches (`PoseSearch`'s
    `foam`: `foam_neutral`'s weighing). Of the re-fits lying under foam (at least `foam_part_share` of
    their inner points on it in each camera, `parts.under_foam`'s level) that reach the candidate's
    fitness less one point's weight (`fitness.point_weight`), both counted so, the first to pass
    detection, fittest so counted first, replaces it. Where a band of foam crosses a squid, a fit
    beside the band, head to tail and off in depth, scores above the whole creature, whose points under
    the band score 0, and fails on parts the foam does not hide (renderer held-out 9 2926: 4.7 % off,
    turned 172 deg, 0.708 against the truth's 0.602; counted so 0.723 against 0.747); `parted_turns`'
    re-fits, scored as the island's GA scored, stay beside the band. Where hue bounds the target and the
    pair has foam (`looks["foam"]`); own random streams (a child of `seed`, FOAM_TURN_STREAMS): every
    other draw is as without the step. `searches`, `looks`: as `grown_outlines`'. One generation per
    step."""
    foam, out = looks.get("foam"), list(results)
    streams = np.random.SeedSequence(seed, spawn_key=(FOAM_TURN_STREAMS,))
    for k, (d, c) in enumerate(results):
        search = searches[c.source]
        if foam is None or search.frame.chroma is not None or not d.fails_on_parts or not np.isfinite(c.fitness):
            continue  # the contour regime, no foam, passes, or fails on more than its parts
        w = point_weight(search.model, search.fit_params)
        score, fits = foam_neutral(search, foam, w), []
        for quarters, ss in zip(PARTED_QUARTERS, streams.spawn(len(PARTED_QUARTERS))):
            R, t = ((c.R, c.position_mm) if quarters == 0
                    else turned_about_centroid(c.R, c.position_mm, c.alpha, search.model, c.aspect, quarters))
            g = yield from search.local_steps(R, t, c.alpha, position_frac=0.03, heading_deg=PARTED_HEADING_DEG,
                                              tilt_deg=QUARTER_TILT_DEG, alpha_frac=0.08,
                                              rng=np.random.default_rng(ss), foam=foam)
            plain = fitness(g.R_model[None], np.asarray(g.position_mm)[None], np.array([g.alpha]), search.model,
                            search.frame, search.rig, search.fit_params)[0]  # the GA's score counts foam
            fits.append(dataclasses.replace(g, fitness=float(plain), source=c.source))
        bar = score(c)[0] - w
        counted = sorted(((score(g), g) for g in fits), key=lambda sg: -sg[0][0])
        for (f, share), g in counted:
            if f >= bar and shares_under_foam(share, p.foam_part_share):
                d_g = detect(g, search.model, search.frame, search.rig, search.fit_params, p, seed=seed, **looks)
                if d_g.passed:
                    out[k] = (d_g, g)
                    break
    return ranked(out, p.passed_standing_ratio)


def _first_passing(fits: list[Candidate], d: Detection, search: PoseSearch, looks: dict, p: EstimatorParams,
                   seed: int) -> tuple[Detection, Candidate] | None:
    """The first of `fits` that passes detection with its outline spilling at most GROWN_SPILL_RATIO of the
    candidate's (`d`), with its detection; None when none does (`grown_turns`)."""
    for g in fits:
        d_g = detect(g, search.model, search.frame, search.rig, search.fit_params, p, seed=seed, **looks)
        if d_g.passed and d_g.outer_on_target <= GROWN_SPILL_RATIO * d.outer_on_target:
            return d_g, g
    return None


def same_surface_first(results: list[tuple[Detection, Candidate]], model: PhotoModel, frame: StereoHue, rig: Rig,
                       grey_frame: StereoGrey, passed_ratio: float) -> list[tuple[Detection, Candidate]]:
    """The candidates `ranked`, after the others those whose two images lie on two surfaces (stereo_plane.
    pairs_other_surfaces: a region of the target's hues wider than the model pairs at a wrong depth too)."""
    on_target = on_target_hue(model, frame.left)
    off = [pairs_other_surfaces(c.R_model, c.position_mm, c.alpha, model, grey_frame.left, grey_frame.right, rig,
                                on_target=on_target) for _, c in results]
    return (ranked([r for r, o in zip(results, off) if not o], passed_ratio)
            + ranked([r for r, o in zip(results, off) if o], passed_ratio))


def ranked(results: list[tuple[Detection, Candidate]], passed_ratio: float) -> list[tuple[Detection, Candidate]]:
    """The candidates ranked by standing (vision/detection.py), then fitness — except that when
    the best-standing one fails detection (a look-alike beside the creature, or a fit spilling
    over the creature's outline), the best-standing candidate that passes goes first if it
    stands at least `passed_ratio` as high as the best-standing that fails for another reason
    than parts on bare water: nearly as far above this pair's null, and passing every test. A
    fit whose absent parts lie on the water's own colour (`Detection.on_bare_water`) is another
    object under the model, not the creature with a test failed, and sets no bar (renderer
    held-out 2 1207: a squid's model on a look-alike standing 0.56, two arm parts on bare
    water, above the creature's fit 1.0 % off at 0.33). Nor does a fit whose body is purer in colour
    than the photo (`Detection.body_purity` over `MAX_BODY_PURITY`): another species under the model
    (harbour 1003: a squid's model on a crab standing 0.72, 1.45, above the creature's fits 2.4-4.5 % off)."""
    out = sorted(results, key=lambda dc: (-dc[0].standing, -dc[1].fitness))
    if out and not out[0][0].passed and out[0][0].standing > 0:
        bar = max((d.standing for d, _ in out
                   if not d.passed and not d.on_bare_water and not d.body_purity > MAX_BODY_PURITY), default=0.0)
        for k, (d, _) in enumerate(out):
            if d.passed and d.standing >= passed_ratio * bar:
                out.insert(0, out.pop(k))
                break
    return out
