"""Detection's outline on another object (vision/detection.py, `bare_parts.off_water`): where hue
bounds the target, a candidate whose outer points lie on another object — on hue, off the target's
hues and a colour edge away from the image's water — is not the creature. Renderer null 1849: a
squid's model shrunk onto the brown band of a fish of another species passed every other test; a
target whose outline touches the most of something else (renderer 1239: 0.11) is found as before."""

from __future__ import annotations

import numpy as np
import pytest
from _bench_scenes import candidate, renderer_scene

from photoservo.config import load_config
from photoservo.vision import detection
from photoservo.vision.bare_parts import off_water, water_chroma
from photoservo.vision.contour import stereo_chroma
from photoservo.vision.estimator import estimate
from photoservo.vision.fitness import stereo_hue
from photoservo.vision.photo_model import target_hue_lut

CFG = load_config()
P = CFG.estimator


def test_a_model_inside_another_species_is_not_found(monkeypatch):
    # benchmarks/accuracy.py --first-null 300: null 349 (seed 1849), a look-alike of another species
    sc, model = renderer_scene(1849, kind="squid", empty=True, distractor=True)
    assert [d["kind"] for d in sc.truth["distractors"]] == ["species"]
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=349)
    assert not est.found
    first = est.candidates[0]
    assert first["off_water"] > detection.MAX_OFF_WATER
    # what the rule takes away: contrast, outline and parts that pass
    assert first["contrast"] >= P.min_contrast and first["outer_on_target"] <= P.max_outer_on_target
    assert first["absent_parts"] <= P.max_absent_parts
    monkeypatch.setattr(detection, "MAX_OFF_WATER", 1.0)
    assert estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=349).found


def test_a_creature_whose_outline_touches_something_else_is_found():
    # renderer 1239 (benchmarks/accuracy.py --first-scene 200: scene 239, a fish, another photo,
    # a look-alike in view)
    sc, model = renderer_scene(1239, kind="fish", other_photo=True, distractor=True)
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=239)
    assert est.found
    truth = np.array(sc.truth["position_mm"])
    assert np.linalg.norm(np.array(est.position_mm) - truth) / truth[2] < 0.05
    assert 0.05 < est.candidates[0]["off_water"] <= detection.MAX_OFF_WATER


def test_off_water_counts_outer_points_a_colour_edge_from_the_water():
    sc, model = renderer_scene(1000, kind="squid")
    frame, chroma = stereo_hue(sc.left, sc.right, CFG.fitness), stereo_chroma(sc.left, sc.right)
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=0)
    c = candidate(est.candidates[0])
    share = off_water(c.R_model, c.position_mm, c.alpha, model, frame, chroma, sc.rig, CFG.fitness.contour_chroma)
    assert share.shape == (2,) and np.all(share <= 0.05)  # a creature on open water
    # the same outline on a pair painted another colour off the creature: all of it on another object
    w = water_chroma(frame.left, chroma.left, target_hue_lut(model.target_hues))
    assert np.all(np.isfinite(w))
    painted = chroma.left.copy()
    painted[..., 0] = np.clip(w[0] + 40, 0, 255)
    moved = type(chroma)(left=painted, right=chroma.right)
    # the image's water colour moves with the paint: nothing is off the water
    again = off_water(c.R_model, c.position_mm, c.alpha, model, frame, moved, sc.rig, CFG.fitness.contour_chroma)
    assert again[0] == pytest.approx(0.0, abs=0.05)
