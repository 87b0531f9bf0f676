"""A fit shrunk inside the creature and turned on it (`candidates.grown_turns`): the island's GA can end
21-37 % too small and turned 20-92 degrees, its outer points on the creature (the outline spills) and
its parts beside the creature's, below the truth's hue fitness. Re-fitted at the four quarter turns,
grown about the photo's centroid, the creature is found; scenes of benchmarks/accuracy.py with its seeds."""

from __future__ import annotations

import numpy as np
from _bench_scenes import found_only_with, found_within_5, harbour_scene, renderer_scene

from photoservo.config import load_config
from photoservo.vision import candidates
from photoservo.vision.appearance import stereo_value
from photoservo.vision.candidates import grown_about_centroid
from photoservo.vision.estimator import estimate
from photoservo.vision.fitness import stereo_hue
from photoservo.vision.parts import foam_marked, foam_share_inner
from photoservo.vision.twins import mask_centroid_mm

CFG = load_config()
P = CFG.estimator


def test_a_squid_fitted_shrunk_and_turned_is_found_regrown():
    # benchmarks/accuracy.py --first-scene 200: scene 240 (seed 1240), a squid, its own photo; the island
    # ends 31 % too small, turned 20 deg, 3.0 % off: outline 0.21 and two parts absent, one on bare water
    sc, model = renderer_scene(1240, kind="squid")
    found_only_with(sc, model, seed=240, step="grown_turns")


def test_a_split_crab_fitted_shrunk_and_turned_a_quarter_is_found_regrown():
    # --first-scene 1100: scene 1138 (seed 2138), a crab across a foam band, its own photo; the island ends
    # 27 % too small and turned 92 deg, 2.4 % off, 4 of 12 parts absent; re-fitted a quarter turn back
    # and grown 1.35 x it passes at the candidate's fitness (within one point's weight)
    sc, model = renderer_scene(2138, kind="crab", split=True)
    found_within_5(sc, model, seed=1138)


def test_a_split_fish_fitted_on_its_tail_half_is_found_when_foam_is_not_counted_against_the_regrown_fit(monkeypatch):
    # --first-scene 1700: scene 1727 (seed 2727), a fish across a foam band, another individual's photo, a
    # look-alike beside it; the island ends on the tail half, 0.62 x the size, outline 0.15, at 0.625 above
    # the truth's 0.608 (a quarter of the truth's inner points lie on foam, which the fitness scores 0).
    # Counting the points on foam as matches (candidates.foam_neutral), a re-fit grown over the band stands
    # within the bar and passes 3.4 % off; without, none does and the scene is not found
    sc, model = renderer_scene(2727, kind="fish", other_photo=True, distractor=True, split=True)
    found_within_5(sc, model, seed=1727)
    monkeypatch.setattr(candidates, "foam_neutral", lambda search, foam, w: (lambda g: (g.fitness, np.zeros(2))))
    assert not estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=1727).found


def test_a_look_alike_whose_re_fit_is_not_under_foam_is_not_weighed_with_foam_counted(monkeypatch):
    # harbour tuned look-alike null 1515 (benchmarks/accuracy.py --generator harbour, a fish's model on
    # another species, seed 15): a re-fit 31 % off with 1.3 % of its points on foam reached the bar by that
    # alone (0.576 + 0.013 against 0.584) and passed. Only re-fits lying under foam (foam_part_share of
    # their inner points on it in each camera) are weighed with foam counted: not found; with every re-fit
    # taken as under foam, found
    sc, model = harbour_scene(1515, kind="fish", empty=True, distractor=True)
    assert not estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=15).found
    foam_neutral = candidates.foam_neutral

    def every_fit_under_foam(search, foam, w):
        score = foam_neutral(search, foam, w)
        return lambda g: (score(g)[0], np.ones(2))

    monkeypatch.setattr(candidates, "foam_neutral", every_fit_under_foam)
    assert estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=15).found


def test_foam_share_inner_reads_the_points_on_foam():
    # the same scene's truth: about a quarter of the inner points lie on the band in both cameras
    sc, model = renderer_scene(2727, kind="fish", other_photo=True, distractor=True, split=True)
    frame = stereo_hue(sc.left, sc.right, CFG.fitness)
    value = stereo_value(sc.left, sc.right)
    foam = foam_marked(frame, value.left, value.right)
    R = np.array(sc.truth["rotation"])
    share = foam_share_inner(R, np.array(sc.truth["position_mm"]), float(sc.truth["alpha_px_per_mm"]), model, foam, sc.rig)
    assert share.shape == (2,) and np.all((0.15 < share) & (share < 0.35))
    assert not foam_share_inner(R, np.array(sc.truth["position_mm"]), float(sc.truth["alpha_px_per_mm"]), model, frame,
                                sc.rig).any()


def test_grown_about_centroid_keeps_the_centroid_in_place():
    sc, model = renderer_scene(1240, kind="squid")
    R = np.array(sc.truth["rotation"])
    t = np.array(sc.truth["position_mm"])
    a = float(sc.truth["alpha_px_per_mm"])
    t2, a2 = grown_about_centroid(R, t, a, model, 1.35)
    assert a2 == a / 1.35
    assert np.allclose(R @ mask_centroid_mm(model, a2) + t2, R @ mask_centroid_mm(model, a) + t)
