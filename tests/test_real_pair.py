"""The real stereo pair (sim/middlebury.py, Middlebury 2014 Motorcycle as scikit-image ships it),
at half size for speed: the rig's conventions against the ground-truth disparity, ground truth
that lands on the target in both images, and the fitness of the true pose standing out from the
same model at random poses of the frame."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("skimage")

from photoservo.config import load_config  # noqa: E402
from photoservo.sim.middlebury import (  # noqa: E402
    TARGETS,
    depth_from_disparity,
    motorcycle_pair,
    motorcycle_rig,
    real_cases,
    red_region,
    right_disparity,
)
from photoservo.vision.genes import GeneSpace  # noqa: E402
from photoservo.vision.fitness import fitness, stereo_hue  # noqa: E402
from photoservo.vision.rig import project_points  # noqa: E402

CFG = load_config(None, ["estimator.z_min_mm=500", "estimator.z_max_mm=5000"])
SCALE = 0.5


@pytest.fixture(scope="module")
def cases():
    return real_cases(CFG.photo_model, scale=SCALE)


def test_rig_reprojects_the_ground_truth_disparity():
    """A left pixel at its true depth projects into the right image at x - d (same row)."""
    left, right, disp = motorcycle_pair(SCALE)
    rig = motorcycle_rig(SCALE)
    assert (rig.left.width, rig.left.height) == (left.shape[1], left.shape[0])
    Z = depth_from_disparity(disp, SCALE)
    rng = np.random.default_rng(0)
    ys, xs = np.nonzero(np.isfinite(Z))
    k = rng.choice(len(xs), 200, replace=False)
    u, v, z = xs[k].astype(float), ys[k].astype(float), Z[ys[k], xs[k]].astype(float)
    X = np.column_stack([(u - rig.left.K[0, 2]) / rig.left.K[0, 0], (v - rig.left.K[1, 2]) / rig.left.K[1, 1],
                         np.ones(len(u))]) * z[:, None]
    uv_r = project_points(X @ rig.R.T + rig.T, rig.right)
    assert np.allclose(uv_r[:, 0], u - disp[ys[k], xs[k]], atol=1e-3)
    assert np.allclose(uv_r[:, 1], v, atol=1e-9)
    # the tank is about 2.3 m away (Middlebury's scene: a motorcycle in a garage)
    tank = red_region(left, tuple(round(c * SCALE) for c in TARGETS["tank"]))
    assert 2100 < np.nanmedian(Z[tank]) < 2500
    # forward warping: a right pixel's disparity points back to a left pixel with the same one
    dr = right_disparity(disp)
    yr, xr = np.nonzero(np.isfinite(dr))
    j = rng.choice(len(xr), 200, replace=False)
    xl = np.rint(xr[j] + dr[yr[j], xr[j]]).astype(int)
    assert np.median(np.abs(disp[yr[j], xl] - dr[yr[j], xr[j]])) < 0.6


def test_three_targets_three_variants_with_truth_on_the_target(cases):
    assert len(cases) == 9
    assert {(c.target, c.variant) for c in cases} == {(t, v) for t in TARGETS for v in ("left", "right", "scaled")}
    for c in cases:
        tr = c.truth
        assert 2000 < tr["distance_mm"] < 4000
        X = np.column_stack([c.model.inner_uv / tr["alpha_px_per_mm"], np.zeros(len(c.model.inner_uv))]) \
            + np.array(tr["position_mm"])
        for cam, Xc, img in ((c.rig.left, X, c.left), (c.rig.right, X @ c.rig.R.T + c.rig.T, c.right)):
            uv = np.rint(project_points(Xc, cam)).astype(int)
            x, y, w, h = tr["box_px"]
            if cam is c.rig.right:  # the target's box in the right image: moved by its disparity
                x -= round(cam.K[0, 0] * c.rig.baseline_mm / tr["distance_mm"] - (cam.K[0, 2] - c.rig.left.K[0, 2]))
            region = red_region(img, (max(0, x - 4), max(0, y - 4), w + 8, h + 8))
            on = region[np.clip(uv[:, 1], 0, img.shape[0] - 1), np.clip(uv[:, 0], 0, img.shape[1] - 1)]
            # in the camera the photo came from nearly every point; in the other one the fork hides
            # a different part of the crate (the left view's cut lacks what the right one shows)
            own = (cam is c.rig.right) == (c.variant == "right")
            assert on.mean() > (0.85 if own else 0.6), (c.target, c.variant, cam is c.rig.right, on.mean())
        # size: the same object seen from either camera or at another photo scale
        assert tr["size_mm"][0] == pytest.approx(c.model.size_px[0] / tr["alpha_px_per_mm"])
    by = {(c.target, c.variant): c.truth["size_mm"][0] for c in cases}
    for t in TARGETS:
        assert by[(t, "scaled")] == pytest.approx(by[(t, "left")], rel=0.05)


def test_true_pose_stands_out_from_the_frame_null(cases):
    """The fitness of the true pose beats the same model at 300 random poses of the search volume."""
    for c in cases:
        frame = stereo_hue(c.left, c.right, CFG.fitness)
        tr = c.truth
        f_true = fitness(np.eye(3), np.array(tr["position_mm"]), tr["alpha_px_per_mm"], c.model, frame, c.rig,
                         CFG.fitness)[0]
        space = GeneSpace("image", c.rig, c.model, CFG.estimator)
        R, t, a, ok = space.decode(space.full_region().sample(np.random.default_rng(1), 600))
        null = fitness(R[ok][:300], t[ok][:300], a[ok][:300], c.model, frame, c.rig, CFG.fitness)
        assert f_true > np.percentile(null, 99), (c.target, c.variant, f_true, np.percentile(null, 99))


def test_silhouette_seeds_land_on_the_target(cases):
    """The target's hues (red widened by the hue tolerance) also cover the garage's wood and floor;
    the distinctive-hue weights and the photo's silhouette (vision/silhouette.py) still put one of
    the two best seed pairs (each seeds a GA island) on the target in every case, near its true depth."""
    from photoservo.vision.silhouette import distinctive_weight, silhouette_pairs

    frame = stereo_hue(cases[0].left, cases[0].right, CFG.fitness)
    hued = frame.left[frame.left < 180]
    for c in cases:
        assert c.model.target_hues[hued].mean() > 0.9  # target hues everywhere: blobs cannot seed
        w = distinctive_weight(frame.left, frame.right, c.model)
        assert w[hued].mean() < 0.3 and w[2] > 0.7  # the frame's hues weigh little, the red much
        x, y, w_, h = c.truth["box_px"]
        assert any(x <= bp.left.centroid[0] <= x + w_ and y <= bp.left.centroid[1] <= y + h
                   and abs(bp.position_mm[2] / c.truth["distance_mm"] - 1) < 0.2
                   for bp in silhouette_pairs(frame.left, frame.right, c.model, c.rig, CFG.estimator)[:2]), \
            (c.target, c.variant)


def test_estimate_finds_the_tank_and_no_wrong_object(cases):
    """From the default volume (depth 0.5-5 m): the tank cut from the left image is found at its
    true depth; whatever the estimator says on the other cases, it never says 'found' on another
    object (the candidate that stands out most from what a search of this pair finds elsewhere at
    its scale is the estimate: a tiny fit on a red badge stands out less than the target)."""
    from photoservo.vision.estimator import estimate

    for c in cases:
        if c.variant != "left":
            continue
        est = estimate(c.model, c.left, c.right, c.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=0)
        tr = c.truth
        if c.target == "tank":
            assert est.found
            assert abs(est.position_mm[2] / tr["distance_mm"] - 1) < 0.05
        if est.found:
            uv = project_points(est.position_mm, c.rig.left)
            x, y, w, h = tr["box_px"]
            assert x <= uv[0] <= x + w and y <= uv[1] <= y + h, (c.target, uv)


@pytest.mark.parametrize("target", ["fender", "crate"])
def test_estimate_finds_the_target_at_full_size(target):
    """Cut from the left image, at full size, seed 0: found, at its depth and size. The fender (a
    thin curved shell): the choice among candidates compares each with the same model at its
    apparent size anywhere in the volume (vision/detection.py `standing`): a fit shrunk onto a
    small red spot at another depth stood above the fender when compared only with its own depth,
    where nothing else is red. The crate: found 24 % too small by the paper's outer rule (the
    garage's wood within the red's hue tolerance, outer points cost the same on the crate as off
    it); the contour rule (vision/contour.py) pins its size."""
    from photoservo.vision.estimator import estimate

    c, = real_cases(CFG.photo_model, targets=(target,), variants=("left",))
    est = estimate(c.model, c.left, c.right, c.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=0)
    tr = c.truth
    assert est.found
    x, y, w, h = tr["box_px"]
    uv = project_points(est.position_mm, c.rig.left)
    assert x <= uv[0] <= x + w and y <= uv[1] <= y + h
    assert abs(est.position_mm[2] / tr["distance_mm"] - 1) < 0.05
    assert abs(tr["alpha_px_per_mm"] / est.alpha_px_per_mm - 1) < 0.15


def test_the_crate_cut_from_the_right_image_is_grown_off_the_ridge_inside_it(monkeypatch):
    """The crate cut from the right image, full size, seed 0. In the left camera the fork hides ~55
    of its 381 inner points at the truth; fits 0.7-0.85x its size inside the red score ~0.85 by the
    contour rule and the island's GA settles there (18 % too small here), while the fitness peaks at
    0.90-0.91 at 0.9-1.05x. The leading island's fit refined and grown (`PoseSearch.grown_steps`,
    `[estimator] contour_grow`) reaches the peak. (The layout re-fit after the slide, `candidates.layout_refit`,
    reaches it too, 0.9 %, without the grown fits: left out here, this judges the grown fits.)"""
    import dataclasses

    from photoservo.vision import candidates
    from photoservo.vision.estimator import estimate

    monkeypatch.setattr(candidates, "layout_refit", _unchanged)

    c, = real_cases(CFG.photo_model, targets=("crate",), variants=("right",))
    tr = c.truth
    size = {}
    for grow in (1.0, CFG.estimator.contour_grow):
        p = dataclasses.replace(CFG.estimator, contour_grow=grow)
        est = estimate(c.model, c.left, c.right, c.rig, CFG.ga, p, CFG.fitness, seed=0)
        assert est.found
        x, y, w, h = tr["box_px"]
        uv = project_points(est.position_mm, c.rig.left)
        assert x <= uv[0] <= x + w and y <= uv[1] <= y + h
        assert abs(est.position_mm[2] / tr["distance_mm"] - 1) < 0.05
        size[grow] = abs(tr["alpha_px_per_mm"] / est.alpha_px_per_mm - 1)
    assert size[1.0] > 0.15 and size[CFG.estimator.contour_grow] < 0.1, size


def test_the_best_candidate_lies_on_the_fender_cut_from_the_right_image():
    """The fender cut from the right image, full size, estimator seed 2: the best candidate (the
    estimate, found or not) lies on the fender. Candidates are ranked by `standing`, against the
    (1 - 1/n) quantile of the model's null at any depth, n the image's model-sized places (~500
    for a fit shrunk onto the motorcycle's frame): from 40 or 160 draws that quantile is their
    largest, low by chance often enough that here a frame fit stood above the fender."""
    from photoservo.vision.estimator import estimate

    c, = real_cases(CFG.photo_model, targets=("fender",), variants=("right",))
    est = estimate(c.model, c.left, c.right, c.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=2)
    x, y, w, h = c.truth["box_px"]
    uv = project_points(np.array(est.candidates[0]["position_mm"]), c.rig.left)
    assert x <= uv[0] <= x + w and y <= uv[1] <= y + h, uv


def test_every_true_pose_passes_detection_at_full_size():
    """The true pose of every case, full size, passes `detect`, outline check included. 97-99 % of
    the pair's hued pixels lie within each model's target hues (wood, cardboard and orange boxes
    within the red's tolerance), so a true target's outer points land on target hue as often as
    the null placements' do (median ~0.5, widely spread): the outline check's reference is the
    null's upper share (`OUTLINE_NULL_QUANTILE`), not its median, which rejected the fender cut
    from the right image and the crate at 0.6x."""
    from photoservo.vision.detection import detect
    from photoservo.vision.estimator import search_frame
    from photoservo.vision.pose_search import Candidate

    for c in real_cases(CFG.photo_model):
        plain = stereo_hue(c.left, c.right, CFG.fitness)
        # ...by the paper's rule and by the contour rule the estimator scores this pair with
        # (vision/contour.py: outer points on target hue judged by colour edges)
        for frame in (plain, search_frame(plain, c.model, c.left, c.right, CFG.estimator)):
            tr = c.truth
            d = detect(Candidate(np.eye(3), np.array(tr["position_mm"]), tr["alpha_px_per_mm"], 0.0, 0, "truth"),
                       c.model, frame, c.rig, CFG.fitness, CFG.estimator)
            assert d.passed, (c.target, c.variant, frame.chroma is not None, d.contrast, d.outer_on_target)


def test_the_crate_at_0_6x_is_not_grown_past_it_on_a_point_of_fitness(monkeypatch):
    """The crate's 0.6x photo (89 inner + 26 outer points), full size, estimator seed 4: the leading
    island ends 7 % off in size; grown by 1.2 the short GA finds a fit 30 % too large that scores
    0.004 higher, less than one sampling point (`fitness.point_weight`, 1/115 = 0.0087). A grown fit
    is kept only when it wins by more than that (`PoseSearch.grown_steps`' min_gain); with no margin
    the estimate is the overshoot (the shrunk turns after the grown fits, `candidates.shrunk_turns`,
    would take it back, 2.4 % off: left out of that case, so that it measures the margin alone)."""
    from photoservo.vision import candidates, estimator

    c, = real_cases(CFG.photo_model, targets=("crate",), variants=("scaled",))
    tr = c.truth
    size = {}
    for margin in (True, False):
        if not margin:
            monkeypatch.setattr(candidates, "point_weight", lambda model, params: 0.0)
            monkeypatch.setattr(candidates, "shrunk_turns", _unchanged)
        est = estimator.estimate(c.model, c.left, c.right, c.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=4)
        assert est.found
        size[margin] = abs(tr["alpha_px_per_mm"] / est.alpha_px_per_mm - 1)
    assert size[True] < 0.15 < size[False], size


def test_stereo_depth_ratio_finds_the_surface_under_a_pose(cases):
    """`stereo_plane.stereo_depth_ratio` on the half-size pair: at the crate's true pose both images
    put its surface at the pose's depth (ratio ~1); the same left image at 0.7 of the depth (alpha
    / 0.7: the model as large in the left image) pairs it with the crate 1/0.7 further away."""
    from photoservo.vision.photo_model import HUE_BINS
    from photoservo.vision.sampling import grey
    from photoservo.vision.stereo_plane import pairs_other_surfaces, stereo_depth_ratio

    c = next(c for c in cases if (c.target, c.variant) == ("crate", "left"))
    lut = np.zeros(256, bool)
    lut[:HUE_BINS] = np.asarray(c.model.target_hues, bool)
    on_target = lut[stereo_hue(c.left, c.right, CFG.fitness).left]
    t, a = np.array(c.truth["position_mm"]), c.truth["alpha_px_per_mm"]
    gl, gr = grey(c.left), grey(c.right)
    for k in (1.0, 0.7):
        r = stereo_depth_ratio(np.eye(3), k * t, a / k, c.model, gl, gr, c.rig, on_target=on_target)
        assert abs(r * k - 1) < 0.05, (k, r)
        assert pairs_other_surfaces(np.eye(3), k * t, a / k, c.model, gl, gr, c.rig, on_target=on_target) == (k != 1.0)


def test_the_crate_at_0_6x_is_not_a_pose_pairing_two_parts_of_it():
    """The crate's 0.6x photo, full size, estimator seed 5: an island ends on the crate in the left
    image at 2.4 m (the crate is at 3.7 m), its right image on the crate's left part - the crate,
    wider in the right image than the photo, fits the small model at two disparities; it scores
    0.948 and stood above the island at the crate's depth (0.943). Both images at its pose put the
    surface 1.57x further (`stereo_depth_ratio`): ranked after the others, the estimate is at the
    crate's depth."""
    from photoservo.vision.estimator import estimate

    c, = real_cases(CFG.photo_model, targets=("crate",), variants=("scaled",))
    est = estimate(c.model, c.left, c.right, c.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=5)
    assert est.found
    assert abs(est.position_mm[2] / c.truth["distance_mm"] - 1) < 0.05


def test_onto_surface_slides_a_fit_to_the_depth_both_images_see(cases):
    """`stereo_plane.onto_surface` on the half-size pair: the crate's true pose moved 10 % nearer
    along its line of sight (alpha / 0.9: the same left image) is slid back to the crate's depth and
    re-scored; a tolerance of 0 keeps it where it is when the slid pose scores lower."""
    import dataclasses

    from photoservo.vision.estimator import search_frame
    from photoservo.vision.pose_search import Candidate, PoseSearch
    from photoservo.vision.stereo_plane import onto_surface

    c = next(c for c in cases if (c.target, c.variant) == ("crate", "left"))
    frame = search_frame(stereo_hue(c.left, c.right, CFG.fitness), c.model, c.left, c.right, CFG.estimator)
    search = PoseSearch(c.model, c.rig, frame, CFG.ga, CFG.estimator, CFG.fitness, np.random.default_rng(0))
    t, a = 0.9 * np.array(c.truth["position_mm"]), c.truth["alpha_px_per_mm"] / 0.9
    f0 = float(fitness(np.eye(3)[None], t[None], np.array([a]), c.model, frame, c.rig, CFG.fitness)[0])
    near = Candidate(R=np.eye(3), position_mm=t, alpha=a, fitness=f0, generations=0, source="blob 0")
    slid = onto_surface(near, search, c.left, c.right, tol=1.0)
    assert abs(slid.position_mm[2] / c.truth["distance_mm"] - 1) < 0.04, slid.position_mm
    assert abs(slid.alpha * slid.position_mm[2] / (a * t[2]) - 1) < 1e-9  # the same left image
    f1 = float(fitness(np.eye(3)[None], slid.position_mm[None], np.array([slid.alpha]), c.model, frame, c.rig,
                       CFG.fitness)[0])
    assert slid.fitness == f1
    kept = onto_surface(dataclasses.replace(near, fitness=f1 + 0.5), search, c.left, c.right, tol=0.0)
    assert kept.position_mm[2] == t[2]


def test_the_crate_cut_from_the_right_image_is_turned_a_quarter_off_the_ridge(monkeypatch):
    """The crate cut from the right image, full size, estimator seed 4: the leading island ends turned
    ~96 degrees, 25 % too small (0.839: a fit of the crate's long side across its short one, on a broad
    ridge inside the red); grown in place it stays there. Its quarter twins (`candidates.quarter_twins`:
    turned 90 degrees either way about the mask's centroid, grown and shrunk by the photo's elongation)
    reach the peak at the crate's heading and size."""
    size = _size_with_and_without(monkeypatch, "right", 4, "quarter_twins")
    assert size[True] < 0.15 < 0.2 < size[False], size


def _unchanged(search, cand, *args):
    """A refinement step of `candidates` that leaves the fit as it is (a generator, as the step it
    stands for)."""
    return cand
    yield


def _size_with_and_without(monkeypatch, variant: str, seed: int, step: str) -> dict[bool, float]:
    """The crate's photo `variant`, full size: the estimate's size error (`_crate_size`) with the
    refinement `candidates.<step>` (True) and with it leaving the fit as it is (False)."""
    from photoservo.vision import candidates

    size = {True: _crate_size(variant, seed)}
    monkeypatch.setattr(candidates, step, _unchanged)
    size[False] = _crate_size(variant, seed)
    return size


def _crate_size(variant: str, seed: int) -> float:
    """The crate's photo `variant`, full size, estimator seed `seed`: the estimate's size error
    (|alpha_true / alpha - 1|); found and within 5 % in depth."""
    from photoservo.vision import estimator

    c, = real_cases(CFG.photo_model, targets=("crate",), variants=(variant,))
    tr = c.truth
    est = estimator.estimate(c.model, c.left, c.right, c.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=seed)
    assert est.found
    assert abs(est.position_mm[2] / tr["distance_mm"] - 1) < 0.05
    return abs(tr["alpha_px_per_mm"] / est.alpha_px_per_mm - 1)


def test_a_fork_before_the_crate_does_not_put_its_fit_on_two_surfaces():
    """The crate cut from the right image, full size, estimator seed 12: the fit on the crate (1.3 % near)
    has 54 inner points matched along their lines of sight, 25 at the fork's depth (2.3 m: the textured
    patches lie along the fork that crosses the crate in the left image) and 23 at its own; with the
    median of all (0.63) its two images were taken to lie on two surfaces and it ranked after two fits
    on the motorcycle, one of them the estimate (`stereo_plane.densest_median`: the pose's own depth
    when at least 20 points see it). Now the estimate is the crate."""
    from photoservo.vision.estimator import estimate

    c, = real_cases(CFG.photo_model, targets=("crate",), variants=("right",))
    est = estimate(c.model, c.left, c.right, c.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=12)
    assert est.found
    x, y, w, h = c.truth["box_px"]
    uv = project_points(est.position_mm, c.rig.left)
    assert x <= uv[0] <= x + w and y <= uv[1] <= y + h, uv
    assert abs(est.position_mm[2] / c.truth["distance_mm"] - 1) < 0.05


def test_the_crate_cut_from_the_left_image_is_turned_and_shrunk_off_the_ridge_past_it(monkeypatch):
    """The crate cut from the left image (76 x 75 px: a square photo), full size, estimator seed 3: the
    leading island ends turned ~106 degrees and 22 % too large (0.858, the truth 0.890), on a ridge of
    fits grown past the crate; its quarter twins turn it at that size (the photo's elongation is 1.01)
    and stay below it. Turned and shrunk by the grown fits' first factor (`candidates.shrunk_turns`) its
    short GAs reach the peak at the crate's heading and size. (The hue layout's grown box seeds an
    island at the crate's size too, which reaches it without the shrunk turns, 5 % off: the shrunk
    turns are judged without the grown islands, the answer with both.)"""
    from photoservo.vision import hue_layout

    assert _crate_size("left", 3) < 0.05
    monkeypatch.setattr(hue_layout, "GROWN_ISLANDS", 0)
    size = _size_with_and_without(monkeypatch, "left", 3, "shrunk_turns")
    assert size[True] < 0.15 < 0.2 < size[False], size


def test_the_crate_cut_from_the_left_image_is_shrunk_before_it_is_turned_a_quarter(monkeypatch):
    """The crate cut from the left image, full size, estimator seed 17: the leading island ends turned
    ~100 degrees and grown past the crate. Its quarter twins, tried first, turned it to the crate's
    heading at that grown size (+24 %), where the shrunk turns (half and quarter turns) find nothing
    better; the shrunk turns tried first, from the island's own heading, reach the peak at the crate's
    size (`candidates.refined`)."""
    import math

    from photoservo.vision import candidates

    shrunk, quarter = candidates.shrunk_turns, candidates.quarter_twins
    size = {True: _crate_size("left", 17)}
    # the order alone: without the ladder run again after a slide beyond STEREO_DEPTH_TOL, which reaches
    # the peak from the quarter twins' grown fit too (size 0.3 % either way)
    monkeypatch.setattr(candidates, "slid_far", lambda c, slid: False)
    monkeypatch.setattr(candidates, "shrunk_turns", lambda search, c, f, gain: quarter(search, c, gain))
    monkeypatch.setattr(candidates, "quarter_twins",
                        lambda search, c, gain: shrunk(search, c, math.sqrt(CFG.estimator.contour_grow), gain))
    size[False] = _crate_size("left", 17)  # the quarter twins first (each still draws its own streams in turn)
    assert size[True] < 0.15 < 0.2 < size[False], size


def test_a_fit_too_near_on_the_crate_is_slid_onto_it_not_ranked_last(monkeypatch):
    """The crate cut from the right image, full size, estimator seeds 14 and 24: the leading island's fit
    has its left image on the crate and its right image on another part of the red, 32 and 14 % too
    near; `onto_surface` left it there when both images put the surface more than STEREO_DEPTH_TOL
    further, and it ranked last (`same_surface_first`): the answer was a fit on the ridge inside the
    crate (seed 14, 26 % small) or on another object (seed 24, 39 % off in depth). Slid onto the depth
    both images see, it is the answer, on the crate, within 5 % in depth and 15 % in size."""
    from photoservo.vision import candidates, estimator
    from photoservo.vision.sampling import grey
    from photoservo.vision.stereo_plane import STEREO_DEPTH_TOL, on_target_hue, onto_surface, stereo_depth_ratio

    c, = real_cases(CFG.photo_model, targets=("crate",), variants=("right",))
    tr, (x, y, w, h) = c.truth, c.truth["box_px"]

    def answers():
        out = []
        for seed in (14, 24):
            est = estimator.estimate(c.model, c.left, c.right, c.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=seed)
            if not est.found:
                out.append((False, 1.0, 1.0))
                continue
            u, v = project_points(est.position_mm, c.rig.left)
            out.append((x <= u <= x + w and y <= v <= y + h,
                        abs(est.position_mm[2] / tr["distance_mm"] - 1),
                        abs(tr["alpha_px_per_mm"] / est.alpha_px_per_mm - 1)))
        return out

    def within_tol(cand, search, left, right, tol):  # the slide as it was: only within STEREO_DEPTH_TOL
        r = stereo_depth_ratio(cand.R_model, cand.position_mm, cand.alpha, search.model, grey(left), grey(right),
                               search.rig, on_target=on_target_hue(search.model, search.frame.left), cluster=True)
        return cand if abs(np.log(r)) > np.log(STEREO_DEPTH_TOL) else onto_surface(cand, search, left, right, tol)

    slid = answers()
    assert all(right and depth < 0.05 and size < 0.15 for right, depth, size in slid), slid
    monkeypatch.setattr(candidates, "onto_surface", within_tol)
    (right14, _, size14), (right24, depth24, _) = answers()
    assert size14 > 0.2 and not (right24 and depth24 < 0.05), (size14, right24, depth24)


def test_a_fit_standing_no_higher_than_the_best_elsewhere_does_not_pass():
    """The fender at 0.6x, seed 0, full size: found at its place; the candidates behind it include a
    fit 78 % small on another object that passed detection standing -0.01 (what a search of the pair
    at its scale finds elsewhere scores as well: vision/detection.py). No candidate standing at or
    below 0 passes, and the answer stands far above (0.88)."""
    from photoservo.vision.estimator import estimate

    c, = real_cases(CFG.photo_model, targets=("fender",), variants=("scaled",))
    est = estimate(c.model, c.left, c.right, c.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=0)
    assert est.found
    x, y, w, h = c.truth["box_px"]
    uv = project_points(est.position_mm, c.rig.left)
    assert x <= uv[0] <= x + w and y <= uv[1] <= y + h
    assert est.candidates[0]["standing"] > 0.5
    low = [k for k in est.candidates if k["standing"] <= 0]
    assert low and not any(k["found"] for k in low)


def test_a_fit_slid_from_two_surfaces_onto_the_crate_is_refined_again_there(monkeypatch):
    """The crate cut from the right image, full size, estimator seed 43: the leading island's fit is
    refined (grown, shrunk and quarter turns) at 2.27 m, 39 % too near, with its two images on two
    parts of the red, then slid onto the depth both images see (3.71 m) at 0.741, 20 % small, and an
    unrefined island's fit (0.806, 16.5 % small) became the answer. Refined again at the slid depth
    (`candidates.contour_ladder`) and slid again, it is the answer within 5 % in depth and size; with
    the second ladder off (`candidates.slid_far` False) the answer misses on size. (Without the layout re-fit
    after it, `candidates.layout_refit`, which moves this answer from 2.4 to 5.2 %: this judges the ladder.)"""
    from photoservo.vision import candidates

    monkeypatch.setattr(candidates, "layout_refit", _unchanged)
    size = {True: _crate_size("right", 43)}
    monkeypatch.setattr(candidates, "slid_far", lambda c, slid: False)
    size[False] = _crate_size("right", 43)
    assert size[True] < 0.05 and size[False] > 0.15, size


def test_the_tank_at_0_6x_is_re_fitted_by_its_grey_layout(monkeypatch):
    """The tank cut from the left image at 0.6x, full size, estimator seed 5: the fitness alone ends on a fit
    15.9 % small and tilted 28 degrees (0.871, above the truth's 0.802; its grey layout 0.42 against the
    truth's 0.68). Re-fitted with the layout beside the fitness (`candidates.layout_refit`) it is found
    within 5 % in size and depth, on the tank; with the re-fit leaving the fit as it is, it misses on size."""
    from photoservo.vision import candidates, estimator

    c, = real_cases(CFG.photo_model, targets=("tank",), variants=("scaled",))
    tr, (x, y, w, h) = c.truth, c.truth["box_px"]

    def size() -> float:
        est = estimator.estimate(c.model, c.left, c.right, c.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=5)
        u, v = project_points(est.position_mm, c.rig.left)
        assert est.found and x <= u <= x + w and y <= v <= y + h
        assert abs(est.position_mm[2] / tr["distance_mm"] - 1) < 0.05
        return abs(tr["alpha_px_per_mm"] / est.alpha_px_per_mm - 1)

    with_layout = size()
    monkeypatch.setattr(candidates, "layout_refit", _unchanged)
    assert with_layout < 0.05 and size() > 0.15, with_layout


def test_a_layout_re_fit_that_only_rises_in_fitness_leaves_the_crate_as_it_was(monkeypatch):
    """The crate cut from the left image, full size, estimator seed 20: the answer is within 5 % in size (its
    grey layout -0.15, the truth's 0.68). The layout re-fit (`candidates.layout_refit`) ends on a fit 18.6 %
    off, fitter (0.757 -> 0.840) but no better laid out (-0.15 -> -0.13): the layout did not choose it, so the
    fit stays (LAYOUT_RISE); without that condition the re-fit replaces it and the crate misses on size."""
    from photoservo.vision import candidates

    size = {True: _crate_size("left", 20)}
    monkeypatch.setattr(candidates, "LAYOUT_RISE", -2.0)
    size[False] = _crate_size("left", 20)
    assert size[True] < 0.05 and size[False] > 0.15, size


def test_the_fender_at_0_6x_is_too_few_points_for_a_layout_re_fit(monkeypatch):
    """The fender's 0.6x photo, full size, estimator seed 19: 81 inner points, a grey layout too
    noisy to tell a rise of LAYOUT_RISE (`candidates.layout_noisy`; the tank at 0.6x, 228 points, is re-fitted).
    Re-fitted all the same, its layout rises 0.24 -> 0.55 on a fit 20.9 % off in size; left as it is, 12.0 %."""
    from photoservo.vision import candidates, estimator

    fender, = real_cases(CFG.photo_model, targets=("fender",), variants=("scaled",))
    tank, = real_cases(CFG.photo_model, targets=("tank",), variants=("scaled",))
    assert candidates.layout_noisy(fender.model) and not candidates.layout_noisy(tank.model)

    def size() -> float:
        est = estimator.estimate(fender.model, fender.left, fender.right, fender.rig, CFG.ga, CFG.estimator,
                                 CFG.fitness, seed=19)
        assert est.found and abs(est.position_mm[2] / fender.truth["distance_mm"] - 1) < 0.05
        return abs(fender.truth["alpha_px_per_mm"] / est.alpha_px_per_mm - 1)

    noisy = size()
    monkeypatch.setattr(candidates, "layout_noisy", lambda model: False)
    assert noisy < 0.15 < size(), noisy
