"""Detection's outline in the contour regime (vision/detection.py, `contour.judged_share`): where the
target's hues are everywhere the contour rule sees the outline only through the outer points it
judges (at least MIN_GAP_PX from their inner neighbour). Harbour null 1812 (empty water of a
fish's hues, a leaf on it): the fish's model fitted 14 px long on the leaf had none judged, spilled
nothing and passed; a fit the rule can judge is found as before (many-hued fish 1700)."""

from __future__ import annotations

import dataclasses

import numpy as np
from _bench_scenes import candidate, harbour_scene

from photoservo.config import load_config
from photoservo.vision import detection
from photoservo.vision.contour import judged_share, stereo_chroma
from photoservo.vision.estimator import estimate, search_frame
from photoservo.vision.fitness import stereo_hue

CFG = load_config()
P = CFG.estimator


def test_a_fit_too_small_for_its_outline_to_be_judged_is_not_found_on_empty_water():
    # benchmarks/accuracy.py --generator harbour --first-null 300: null 312 (seed 1812), empty
    sc, model = harbour_scene(1812, kind="fish", empty=True)
    assert sc.truth["distractors"] == []
    frame = search_frame(stereo_hue(sc.left, sc.right, CFG.fitness), model, sc.left, sc.right, P)
    assert frame.chroma is not None  # the contour regime: the water carries the fish's hues
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=312)
    assert not est.found
    first = est.candidates[0]
    # what the rule takes away: a contrast and an outline that pass, nothing of the outline judged
    assert first["contrast"] >= P.min_contrast and first["outer_on_target"] <= P.max_outer_on_target
    assert first["outline_judged"] < detection.MIN_JUDGED_SHARE
    c = candidate(first)
    assert np.all(judged_share(c.R_model, c.position_mm, c.alpha, model, frame, frame.chroma, sc.rig,
                               CFG.fitness) == 0.0)


def test_a_many_hued_fish_the_contour_rule_can_judge_is_found():
    # benchmarks/accuracy.py --many-hued: fish 0 (seed 1700), estimated with seed 0, within 5 % of its depth
    sc, model = harbour_scene(1700, kind="fish", many_hued=True)
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=0)
    off = np.array(est.position_mm if est.found else np.full(3, np.inf)) - sc.truth["position_mm"]
    assert np.linalg.norm(off) < 0.05 * sc.truth["position_mm"][2]
    assert est.candidates[0]["outline_judged"] >= 0.3


def test_the_hue_regime_does_not_judge_the_outline():
    sc, model = harbour_scene(1000, kind="squid")
    frame = stereo_hue(sc.left, sc.right, CFG.fitness)
    assert search_frame(frame, model, sc.left, sc.right, P).chroma is None
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=0)
    assert all(c["outline_judged"] is None for c in est.candidates)
    # judged_share itself on this pair's chroma: a fit shrunk 20x has no pair far enough apart to judge
    c = candidate(est.candidates[0])
    chroma = stereo_chroma(sc.left, sc.right)
    small = judged_share(c.R_model, c.position_mm, 20 * c.alpha, model, dataclasses.replace(frame, chroma=chroma),
                         chroma, sc.rig, CFG.fitness)
    assert small.shape == (2,) and np.all(small == 0.0)
