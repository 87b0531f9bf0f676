"""The estimator (vision/estimator.py) on small seeded synthetic scenes: it finds the creature from
the default search volume, repeats itself with a seed, says found=false on empty water."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from photoservo.config import load_config
from photoservo.vision.estimator import estimate
from photoservo.vision.genes import GeneSpace
from photoservo.vision.pose_search import Convergence, PoseSearch
from photoservo.vision.twins import reflected_rotation
from photoservo.vision.seeding import blob_pairs
from photoservo.vision.fitness import stereo_hue
from photoservo.vision.photo_model import build_photo_model
from photoservo.geometry import heading_tilt_error, rotation_from_heading_tilt
from photoservo.sim.scenes import random_scene

CFG = load_config()


@pytest.fixture(scope="module")
def scene():
    sc = random_scene(11, CFG.synthetic, CFG.photo_model, kind="squid", effects=("waves", "noise"),
                      distance_mm=700.0, tilt_deg=15.0)
    return sc, build_photo_model(sc.photo, CFG.photo_model)


def truth(sc):
    t = sc.truth
    return np.array(t["rotation"]), np.array(t["position_mm"]), t["alpha_px_per_mm"]


def test_finds_the_creature_from_the_default_volume(scene):
    sc, model = scene
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=0)
    R, t, alpha = truth(sc)
    assert est.found and est.confidence > 0.5
    assert np.linalg.norm(est.position_mm - t) < 0.03 * t[2]
    assert abs(est.alpha_px_per_mm / alpha - 1) < 0.08
    heading, _ = heading_tilt_error(R, est.rotation)
    assert heading < 5.0
    # converged, not stopped at the cap
    assert CFG.estimator.min_generations < est.generations < CFG.estimator.max_generations
    js = est.to_json()
    assert set(js) >= {"found", "position_mm", "rotation", "alpha_px_per_mm", "size_mm", "fitness",
                       "generations", "seconds"}
    ax, ay = js["alpha_xy_px_per_mm"]
    assert js["size_mm"] == pytest.approx([model.size_px[0] / ax, model.size_px[1] / ay])
    assert ax * ay == pytest.approx(est.alpha_px_per_mm**2)  # alpha: the geometric mean of the two axes
    assert abs(ax / ay - 1) < 0.06  # the same photo: nearly the same ratio along both axes


def test_same_seed_same_estimate(scene):
    sc, model = scene
    a = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=5)
    b = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=5)
    ja, jb = a.to_json(), b.to_json()
    ja.pop("seconds"), jb.pop("seconds")
    assert ja == jb


def test_empty_water_is_not_found():
    sc = random_scene(12, CFG.synthetic, CFG.photo_model, kind="crab", effects=("waves", "glints", "noise"),
                      empty=True)
    model = build_photo_model(sc.photo, CFG.photo_model)
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=0)
    assert not est.found
    js = est.to_json()
    assert js["found"] is False
    assert all(js[k] is None for k in ("position_mm", "rotation", "alpha_px_per_mm", "size_mm"))


def test_blobs_pair_along_epipolar_lines_and_triangulate(scene):
    sc, model = scene
    frame = stereo_hue(sc.left, sc.right, CFG.fitness)
    pairs = blob_pairs(frame.left, frame.right, model, sc.rig, CFG.estimator)
    assert pairs
    _, t, _ = truth(sc)
    # the blob centroid is near the model origin: depth within a few percent
    assert abs(pairs[0].position_mm[2] / t[2] - 1) < 0.05


def test_tracking_api_window_and_new_frame(scene):
    sc, model = scene
    R, t, alpha = truth(sc)
    frame = stereo_hue(sc.left, sc.right, CFG.fitness)
    search = PoseSearch(model, sc.rig, frame, CFG.ga, CFG.estimator, CFG.fitness, np.random.default_rng(0))
    R0 = R @ rotation_from_heading_tilt(math.radians(8), 0.0, 0.0)
    search.set_window(R0, t + [10, -5, 20], alpha * 1.05, position_mm=40, heading_deg=20, tilt_deg=20, alpha_frac=0.2)
    c = search.step(100)
    assert np.linalg.norm(c.position_mm - t) < 0.05 * t[2]
    f_before = c.fitness
    search.set_frame(frame)  # same frame again: scores recomputed, best unchanged
    assert search.best().fitness == pytest.approx(f_before)
    search.reset_full()
    assert search.ga.region.lo[2] == pytest.approx(1000.0 / CFG.estimator.z_max_mm)


def test_gene_space_encode_decode_roundtrip(scene):
    sc, model = scene
    R, t, alpha = truth(sc)
    for kind in ("image", "cartesian"):
        space = GeneSpace(kind, sc.rig, model, CFG.estimator)
        R2, t2, a2, valid = space.decode(space.encode(R, t, alpha))
        assert valid[0] and np.allclose(R2[0], R) and np.allclose(t2[0], t) and a2[0] == pytest.approx(alpha)


def test_compiled_decode_equals_the_numpy_reference(scene):
    """`GeneSpace.decode` (genes_kernel) gives the poses and the validity of `decode_reference`
    for genes inside, at the edge of and outside the search volume, tilts clamped or not."""
    sc, model = scene
    rng = np.random.default_rng(5)
    for kind in ("image", "cartesian"):
        space = GeneSpace(kind, sc.rig, model, CFG.estimator)
        box = space.full_region()
        lo, hi = box.lo - 0.3 * box.width, box.hi + 0.3 * box.width  # a share of them outside the volume
        for tilt_scale in (0.5, 3.0):  # no tilt clamped / some clamped
            g = lo + (hi - lo) * rng.random((400, 7))
            g[:, 4:6] *= tilt_scale
            R, t, a, valid = space.decode(g)
            R0, t0, a0, valid0 = space.decode_reference(g)
            assert np.array_equal(valid, valid0) and 0 < valid.sum() < len(g)
            assert np.allclose(R, R0, rtol=0, atol=1e-14) and np.allclose(t, t0, rtol=1e-14, atol=0)
            assert np.allclose(a, a0, rtol=1e-14, atol=0)


def test_reflected_rotation_mirrors_the_normal_about_the_line_of_sight():
    R = rotation_from_heading_tilt(0.3, 0.25, -0.1)
    t = np.array([50.0, -30.0, 800.0])
    R2 = reflected_rotation(R, t)
    d = t / np.linalg.norm(t)
    assert R2[:, 2] @ d == pytest.approx(R[:, 2] @ d)
    assert np.allclose(R2[:, 2] + R[:, 2], 2 * (R[:, 2] @ d) * d)


def test_convergence_waits_for_patience_and_tolerances():
    p = dataclasses.replace(CFG.estimator, min_generations=5, patience=10, fitness_tol=1e-3, position_tol_mm=1.0)
    conv = Convergence(p)
    R, t = np.eye(3), np.array([0.0, 0.0, 500.0])
    stops = [conv.update(0.5 + 0.01 * min(i, 20), R, t, 1.0) for i in range(40)]
    # improving until generation 20, flat after: converged exactly `patience` generations later
    assert not any(stops[:30]) and stops[30]
    conv = Convergence(p)
    moving = [conv.update(0.9, R, t + [2.0 * i, 0, 0], 1.0) for i in range(40)]
    assert not any(moving)  # the pose keeps moving: not converged


def test_stereo_plane_fit_recovers_the_tilt(scene):
    """Tilt from the disparity gradient (vision/stereo_plane.py): from a pose whose tilt is 12 deg
    off, the plane fitted over the inner points brings the normal back within 6 deg (the rig file
    is off by the scene's calibration error, which alone tips the stereo plane by a few deg)."""
    from photoservo.vision.sampling import grey
    from photoservo.vision.stereo_plane import align_to_plane, fit_target_plane

    sc, model = scene
    R, t, alpha = truth(sc)
    R_off = R @ rotation_from_heading_tilt(0.0, math.radians(12), 0.0)
    on_target = np.zeros(256, bool)
    on_target[:180] = model.target_hues
    frame = stereo_hue(sc.left, sc.right, CFG.fitness)
    plane = fit_target_plane(R_off, t, alpha, model, grey(sc.left), grey(sc.right), sc.rig,
                             on_target=on_target[frame.left])
    assert plane is not None and plane.inliers >= 50
    R2, t2 = align_to_plane(R_off, t, plane)
    _, tilt_before = heading_tilt_error(R, R_off)
    _, tilt_after = heading_tilt_error(R, R2)
    assert tilt_before == pytest.approx(12.0) and tilt_after < 6.0
    assert abs(t2[2] - t[2]) < 0.02 * t[2]


def test_detection_needs_both_cameras_and_the_outline(scene):
    """`detect`: the true pose passes; a model shrunk inside the creature (its outer band lands on
    target hue) fails the outline check even where its inner points all agree."""
    from photoservo.vision.detection import detect
    from photoservo.vision.pose_search import Candidate

    sc, model = scene
    R, t, alpha = truth(sc)
    frame = stereo_hue(sc.left, sc.right, CFG.fitness)
    ok = detect(Candidate(R, t, alpha, 0.0, 0, "truth"), model, frame, sc.rig, CFG.fitness, CFG.estimator)
    assert ok.passed and ok.contrast >= CFG.estimator.min_contrast and ok.outer_on_target < 0.05
    assert ok.null_level < ok.score and ok.threshold == pytest.approx(
        ok.null_level + CFG.estimator.min_contrast * (1 - ok.null_level))
    shrunk = detect(Candidate(R, t, alpha * 1.6, 0.0, 0, "shrunk"), model, frame, sc.rig, CFG.fitness, CFG.estimator)
    assert not shrunk.passed and shrunk.outer_on_target > CFG.estimator.max_outer_on_target
    assert shrunk.confidence < ok.confidence


def test_a_passing_candidate_nearly_as_high_goes_before_a_failing_first():
    """candidates.ranked on hand-made candidates: by standing, but a first that fails detection
    yields to the best passing one standing at least passed_standing_ratio as high."""
    from photoservo.vision.detection import Detection
    from photoservo.vision.candidates import ranked
    from photoservo.vision.pose_search import Candidate

    def cand(x, passed, standing):
        d = Detection(score=0.9, null_level=0.2, contrast=standing, outer_on_target=0.0, passed=passed,
                      confidence=0.9, threshold=0.5, standing=standing)
        return d, Candidate(np.eye(3), np.array([x, 0.0, 600.0]), 2.0, 0.9, 10, "blob")

    def firsts(results, ratio):
        return [c.position_mm[0] for _, c in ranked(results, ratio)]

    near = [cand(1.0, True, 0.50), cand(2.0, False, 0.76), cand(3.0, True, 0.64)]  # 0.64 / 0.76 = 0.84
    assert firsts(near, 0.82) == [3.0, 2.0, 1.0]
    assert firsts(near, 1.0) == [2.0, 3.0, 1.0]  # 1 = by standing only
    far = [cand(1.0, True, 0.10), cand(2.0, False, 0.35)]  # 0.29: a badge-sized fit elsewhere stays behind
    assert firsts(far, 0.82) == [2.0, 1.0]
    assert firsts([cand(1.0, True, 0.3), cand(2.0, True, 0.6)], 0.82) == [2.0, 1.0]  # first passes: unchanged


def test_a_failing_first_with_parts_on_bare_water_sets_no_bar():
    """candidates.ranked: a first that fails because its absent parts lie on bare water (another
    object under the model) does not hold back a passing candidate far below it; one failing for
    another reason still does."""
    from photoservo.vision.candidates import ranked
    from photoservo.vision.detection import Detection
    from photoservo.vision.pose_search import Candidate

    def cand(x, passed, standing, bare=False):
        d = Detection(score=0.9, null_level=0.2, contrast=standing, outer_on_target=0.0, passed=passed,
                      confidence=0.9, threshold=0.5, standing=standing, on_bare_water=bare)
        return d, Candidate(np.eye(3), np.array([x, 0.0, 600.0]), 2.0, 0.9, 10, "blob")

    def firsts(results):
        return [c.position_mm[0] for _, c in ranked(results, 0.82)]

    assert firsts([cand(1.0, True, 0.33), cand(2.0, False, 0.56, bare=True)]) == [1.0, 2.0]
    assert firsts([cand(1.0, True, 0.33), cand(2.0, False, 0.56)]) == [2.0, 1.0]
    # the bar is the best that fails otherwise: 0.33 / 0.45 < 0.82 stays behind it
    assert firsts([cand(1.0, True, 0.33), cand(2.0, False, 0.56, bare=True), cand(3.0, False, 0.45)]) == [2.0, 3.0, 1.0]


@pytest.mark.parametrize("scene, split, fails_on_bare_water", [(1051, False, False), (1207, True, True)])
def test_the_creature_is_found_beside_a_look_alike_that_stands_higher_but_fails(scene, split, fails_on_bare_water):
    """The accuracy benchmark's renderer scenes 1051 and held-out 1207 (a squid, another individual's
    photo, a look-alike in view; 1207 split by foam): the look-alike's fit stands highest and fails
    (1051: the outline test, the creature's fit passing at 0.84 as high; 1207: two arm parts on bare
    water, standing 0.56 against the creature's 0.33), so the creature's fit is the estimate."""
    from photoservo.sim.scenes import EFFECTS

    sc = random_scene(scene, CFG.synthetic, CFG.photo_model, kind="squid", other_photo=True, effects=tuple(EFFECTS),
                      distractor=True, split=split)
    model = build_photo_model(sc.photo, CFG.photo_model)
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=scene - 1000)
    t = np.array(sc.truth["position_mm"])
    assert est.found and np.linalg.norm(est.position_mm - t) < 0.05 * t[2]
    by_standing = max(est.candidates, key=lambda c: c["standing"])
    assert not by_standing["found"] and np.linalg.norm(np.array(by_standing["position_mm"]) - t) > 0.2 * t[2]
    assert (by_standing["bare_parts"] >= 1) == fails_on_bare_water
