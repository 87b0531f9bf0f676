"""Detection's body against the water beside it (vision/detection.py, `bare_parts.body_gap`): where hue
bounds the target, a candidate whose body (inner points on a target hue) stands less than a colour
edge (`[fitness] contour_chroma`, a*b* units) off the water around it in both cameras is not the
creature. Harbour held-out 5 null 2266 (empty water): a squid's model 55 mm long on a dull brown leaf
whose hue falls in the squid's tolerance, 9.8 and 11.4 a*b* units off the water, passed every other
test (contrast 0.42, outline clean, 1 of 12 parts absent)."""

from __future__ import annotations

import numpy as np
from _bench_scenes import candidate, harbour_scene

from photoservo.config import load_config
from photoservo.vision import detection
from photoservo.vision.bare_parts import body_gap
from photoservo.vision.contour import stereo_chroma
from photoservo.vision.estimator import estimate
from photoservo.vision.fitness import project_model, stereo_hue
from photoservo.vision.photo_model import HUE_BINS, target_hue_lut

CFG = load_config()
P = CFG.estimator
EDGE = CFG.fitness.contour_chroma


def test_a_squid_model_on_a_leaf_is_not_found(monkeypatch):
    # benchmarks/accuracy.py --generator harbour --first-null 700: null 766 (seed 2266), empty water
    # with four pieces of debris; the answer sits on a 33 x 11 mm leaf
    sc, model = harbour_scene(2266, kind="squid", empty=True)
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=766)
    assert not est.found
    first = est.candidates[0]
    assert first["body_gap"] < EDGE
    # what the rule takes away: contrast, outline and parts that pass
    assert first["contrast"] >= P.min_contrast and first["outer_on_target"] <= P.max_outer_on_target
    assert first["absent_parts"] <= P.max_absent_parts and first["off_water"] <= detection.MAX_OFF_WATER
    monkeypatch.setattr(detection, "body_gap", lambda *a, **k: np.full(2, np.nan))  # not judged
    # the leaf is flat too: the body's relief (`bare_parts.body_relief`, 0.46) rejects it as well
    assert first["body_relief"] < detection.MIN_BODY_RELIEF
    assert not estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=766).found
    monkeypatch.setattr(detection, "body_relief", lambda *a, **k: np.full(2, np.nan))  # neither judged
    assert estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=766).found


def test_a_creature_stands_a_colour_edge_off_the_water_and_a_body_painted_near_it_does_not():
    # harbour 1033 (another individual's photo, a squid): the tuned set's answer nearest the water
    sc, model = harbour_scene(1033, kind="squid", other_photo=True)
    frame, chroma = stereo_hue(sc.left, sc.right, CFG.fitness), stereo_chroma(sc.left, sc.right)
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=33)
    assert est.found
    c = candidate(est.candidates[0])
    gap = body_gap(c.R_model, c.position_mm, c.alpha, model, frame, chroma, sc.rig)
    assert gap.shape == (2,) and np.all(gap >= 1.5 * EDGE)
    # the body's pixels painted 5 a*b* units off the water beside it: the gap follows the paint
    p = project_model(c.R_model, c.position_mm, c.alpha, model, sc.rig)
    target = target_hue_lut(model.target_hues)
    painted = []
    for uv_in, uv_out, hue, ab in ((p.inner_left[0], p.outer_left[0], frame.left, chroma.left),
                                   (p.inner_right[0], p.outer_right[0], frame.right, chroma.right)):
        ab = ab.copy()
        out = np.round(uv_out).astype(int)
        water = ~target[hue[out[:, 1], out[:, 0]]] & (hue[out[:, 1], out[:, 0]] < HUE_BINS)
        w = np.median(ab[out[water, 1], out[water, 0]].astype(float), axis=0)
        inn = np.round(uv_in).astype(int)
        ab[inn[:, 1], inn[:, 0]] = np.round(w + [3.0, 4.0]).astype(np.uint8)
        painted.append(ab)
    moved = type(chroma)(left=painted[0], right=painted[1])
    again = body_gap(c.R_model, c.position_mm, c.alpha, model, frame, moved, sc.rig)
    assert np.allclose(again, 5.0, atol=1.0)

    # a pair without colour (a compact recording's grey planes, record.planes): not judged
    grey = type(chroma)(left=np.full_like(chroma.left, 128), right=np.full_like(chroma.right, 128))
    assert np.isnan(body_gap(c.R_model, c.position_mm, c.alpha, model, frame, grey, sc.rig)).all()
