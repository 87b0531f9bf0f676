"""Detection's parts check (vision/parts.py): the photo-model's inner points fall into compact
parts; a part whose hued points mostly land off the target's hues is absent. A crab's model
squeezed onto a look-alike of its colour has whole parts on water and is rejected; a creature
under a foam band (parts without hue) and a brighter, darker or colour-cast copy keep theirs."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from photoservo.config import load_config
from photoservo.sim.scenes import EFFECTS, random_scene
from photoservo.vision.detection import detect
from photoservo.vision.estimator import estimate
from photoservo.vision.fitness import StereoHue, inner_hues, stereo_hue
from photoservo.vision.parts import (FOAM, PARTS, absent_flags, absent_parts, absent_share, foam_marked, foam_share_inner,
                                     model_parts, shares_under_foam, under_foam)
from photoservo.vision.photo_model import HUE_BINS, NO_HUE, build_photo_model
from photoservo.vision.pose_search import Candidate

CFG = load_config()
P = CFG.estimator


def _scene(seed, **kw):
    sc = random_scene(seed, CFG.synthetic, CFG.photo_model, effects=EFFECTS, **kw)  # as benchmarks/accuracy.py
    return sc, build_photo_model(sc.photo, CFG.photo_model)


def _truth(sc):
    tr = sc.truth
    return Candidate(np.array(tr["rotation"]), np.array(tr["position_mm"]), tr["alpha_px_per_mm"], 0.0, 0, "truth")


def test_parts_are_compact_deterministic_and_cover_the_model():
    sc, model = _scene(1000, kind="squid")
    labels = model_parts(model.inner_uv)
    assert np.array_equal(labels, model_parts(model.inner_uv))
    assert set(np.unique(labels)) == set(range(PARTS))
    # compact: each point is nearer its own part's centre than any other's (a Voronoi partition)
    centres = np.array([model.inner_uv[labels == k].mean(axis=0) for k in range(PARTS)])
    nearest = ((model.inner_uv[:, None, :] - centres[None]) ** 2).sum(-1).argmin(axis=1)
    assert np.mean(nearest == labels) > 0.98
    assert model_parts(model.inner_uv[:5]).max() == 4


def test_absent_share_counts_parts_off_the_targets_hues_not_parts_without_hue():
    labels = np.repeat(np.arange(4), 10)
    hued = np.ones((2, 40), bool)
    agrees = np.ones((2, 40), bool)
    assert absent_share(hued, agrees, labels) == 0.0
    water = agrees.copy()
    water[1, labels == 3] = False  # one part on the water's hue in the right camera
    assert absent_share(hued, water, labels) == 0.25
    foam = hued.copy()
    foam[:, labels == 3] = False  # the same part under foam: no hue, not counted
    assert absent_share(foam, water & foam, labels) == 0.0
    # a part under foam is not absent, nor does it make the absent ones weigh more: one part on
    # water and one under foam is one part absent of the model's four (not one of the three counted)
    other_foam = hued.copy()
    other_foam[:, labels == 2] = False
    assert absent_share(other_foam, water & other_foam, labels) == 0.25
    assert np.isnan(absent_share(np.zeros((2, 40), bool), agrees, labels))


def test_a_creature_cut_by_foam_keeps_its_parts_at_the_true_pose():
    sc, model = _scene(1004, kind="crab", split=True)
    frame = stereo_hue(sc.left, sc.right, CFG.fitness)
    t = _truth(sc)
    hued = inner_hues(t.R_model, t.position_mm, t.alpha, model, frame, sc.rig) < HUE_BINS
    assert (~hued).mean() > 0.05  # the foam band leaves inner points without hue
    assert absent_parts(t.R_model, t.position_mm, t.alpha, model, frame, sc.rig) <= P.max_absent_parts
    # half the model slid off the creature onto water: its parts there are absent
    off = Candidate(t.R, t.position_mm + t.R @ np.array([0.6 * model.size_px[0] / t.alpha, 0.0, 0.0]), t.alpha, 0.0,
                    0, "off")
    assert absent_parts(off.R_model, off.position_mm, off.alpha, model, frame, sc.rig) > 0.3


@pytest.mark.parametrize("gain_bgr", [1.2, 0.8, (1.08, 1.0, 0.92)], ids=["brighter", "darker", "colour-cast"])
def test_the_parts_decision_is_the_same_on_a_brighter_darker_or_colour_cast_copy(gain_bgr):
    sc, model = _scene(1000, kind="squid")
    t = _truth(sc)

    def cast(img):
        return np.clip(img.astype(np.float64) * np.asarray(gain_bgr), 0, 255).astype(np.uint8)

    a = [detect(t, model, stereo_hue(left, right, CFG.fitness), sc.rig, CFG.fitness, P).absent_parts
         for left, right in ((sc.left, sc.right), (cast(sc.left), cast(sc.right)))]
    assert a[0] <= P.max_absent_parts and a[1] <= P.max_absent_parts


def test_a_crab_model_on_a_squid_of_its_colour_is_not_found():
    """Renderer null scene 1511 of the accuracy benchmark: no crab, a squid look-alike of the
    crab's colour; the crab's model fits the squid's mantle (contrast ~0.6, outline clean) with
    its legs on water. Without the parts check it was a false positive."""
    sc, model = _scene(1511, kind="crab", empty=True, distractor=True)
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=11)
    assert not est.found
    best = est.candidates[0]
    assert best["contrast"] >= P.min_contrast and best["outer_on_target"] <= P.max_outer_on_target
    assert best["absent_parts"] > P.max_absent_parts


def test_another_individual_under_foam_with_its_arm_tips_elsewhere_is_found():
    """Renderer scene 1009 of the accuracy benchmark: a squid from another individual's photo, a
    foam band over a third of it; the model's two arm tips (a few hued points each) lie where that
    individual held them, on water. Counted over the parts with hue (8 of 12 in one camera) that
    was 2 of 8 absent and the squid was not found; over the model's 12 parts it is 2 of 12. (The
    parts at the band are not judged at all where they straddle its foam, `foam_part_share`: the
    count over all parts is checked with every part judged.)"""
    sc, model = _scene(1009, kind="squid", other_photo=True, split=True)
    t = np.array(sc.truth["position_mm"])
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=9)
    assert est.found and np.linalg.norm(est.position_mm - t) <= 0.05 * t[2]
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, dataclasses.replace(P, foam_part_share=1.0), CFG.fitness,
                   seed=9)
    assert est.found
    assert np.linalg.norm(est.position_mm - t) <= 0.05 * t[2]
    best = est.candidates[0]
    assert 0.0 < best["absent_parts"] <= P.max_absent_parts
    frame = stereo_hue(sc.left, sc.right, CFG.fitness)
    c = Candidate(est.rotation, est.position_mm, est.alpha_px_per_mm, 0.0, 0, "estimate",
                  aspect=float(np.sqrt(est.alpha_xy_px_per_mm[1] / est.alpha_xy_px_per_mm[0])))
    h = inner_hues(c.R_model, c.position_mm, c.alpha, model, frame, sc.rig)
    labels = model_parts(model.inner_uv)
    hued_parts = [len(np.unique(labels[(row < HUE_BINS)])) for row in h]
    assert min(hued_parts) < PARTS  # the foam leaves parts without hue: they do not count against it


def test_foam_is_marked_and_a_part_straddling_it_is_not_judged():
    """`foam_marked`: patches of pixels without hue at least as bright as the image's hued median
    are FOAM (shadow, darker, and a one-pixel pale rim stay NO_HUE); where the model lies under
    foam (`under_foam`) a part with `foam_share` of its points on foam is not absent however few
    of its hued points are on a target hue (`absent_flags`)."""
    hue = np.full((40, 60), 100, np.uint8)  # water's hue
    value = np.full((40, 60), 120.0, np.float32)
    hue[:, 28:32], value[:, 28:32] = NO_HUE, 240.0  # a white foam band
    hue[5:8, 5:8], value[5:8, 5:8] = NO_HUE, 20.0  # a shadow
    hue[20, 2:20], value[20, 2:20] = NO_HUE, 160.0  # a pale rim, one pixel wide
    frame = StereoHue(left=hue, right=hue.copy())
    marked = foam_marked(frame, value, value)
    for h in (marked.left, marked.right):
        assert np.all(h[:, 28:32] == FOAM) and np.all(h[5:8, 5:8] == NO_HUE) and np.all(h[20, 2:20] == NO_HUE)
        assert np.count_nonzero(h == 100) == np.count_nonzero(hue == 100)
    assert np.array_equal(frame.left, hue)  # the pair itself is untouched
    labels = np.repeat([0, 1], 10)
    hued = np.ones((1, 20), bool)
    hued[0, 7:10] = False  # part 0: 3 of its 10 points on foam, its 7 hued ones off target
    on = np.zeros((1, 20), bool)
    on[0, 10:] = True
    foam = ~hued
    assert absent_flags(hued, on, labels).tolist() == [[True, False]]
    assert under_foam(foam, 0.15) and not under_foam(foam, 0.2)  # 3 of the model's 20 points on foam
    assert shares_under_foam(foam.mean(axis=1), 0.15) and not shares_under_foam(foam.mean(axis=1), 0.2)
    assert absent_flags(hued, on, labels, foam, 0.1).tolist() == [[False, False]]
    # a model with too few of its points on foam (glitter beside a look-alike) has every part judged
    assert absent_flags(hued, on, labels, foam, 0.2).tolist() == [[True, False]]


def test_a_split_squid_with_a_part_at_the_band_edge_is_found():
    """Renderer held-out scene 1234 of the accuracy benchmark (`--first-scene 200`): a squid cut by
    a foam band, same photo. The GA's best slides along the body (5.7 % off, parts on water) and
    the islands near the truth (1.7-1.8 %) had 2-3 of 12 parts absent, one of them straddling the
    band's pale edge (the bare-water rule then rejects two absent with one bare): not found. With
    the parts on foam unjudged (`[estimator] foam_part_share`) a fit within 2 % passes. Judged, with
    the plane turn on its own stream (fde3377) `parted_turns` finds it 2.75 % off, so the counterfactual
    turns that step off too: the rule, not the plane turn, is what finds it within 2 %."""
    sc, model = _scene(1234, kind="squid", split=True)
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=234)
    t = np.array(sc.truth["position_mm"])
    assert est.found and np.linalg.norm(est.position_mm - t) <= 0.02 * t[2]
    off = estimate(model, sc.left, sc.right, sc.rig, CFG.ga,
                   dataclasses.replace(P, foam_part_share=1.0, parted_turns=False), CFG.fitness, seed=234)
    assert not off.found


def test_under_foam_from_the_mask_and_from_a_poses_shares_agree():
    """`candidates.grown_turns` asks `shares_under_foam` of a pose's `foam_share_inner` what `absent_flags` asks
    `under_foam` of its points on foam: the same answer for a split squid at its true pose, at every level (a
    level between the two cameras' shares: under foam in one camera only is not under foam)."""
    sc, model = _scene(1004, kind="squid", split=True)
    frame = stereo_hue(sc.left, sc.right, CFG.fitness)
    marked = foam_marked(frame, *(np.max(img, axis=2).astype(np.float32) for img in (sc.left, sc.right)))
    t = _truth(sc)
    share = foam_share_inner(t.R_model, t.position_mm, t.alpha, model, marked, sc.rig)
    on_foam = inner_hues(t.R_model, t.position_mm, t.alpha, model, marked, sc.rig) == FOAM
    assert share.min() > 0.05  # the band lies across it in both cameras
    for level in (0.5 * share.min(), share.min(), 0.5 * (share.min() + share.max()) + 1e-9, share.max() + 1e-9):
        assert shares_under_foam(share, level) == under_foam(on_foam, level) == (level <= share.min())
