"""A fit shrunk inside the creature and turned on it (`candidates.grown_turns`): the island's GA can end
21-37 % too small and turned 20-92 degrees, its outer points on the creature (the outline spills) and
its parts beside the creature's, below the truth's hue fitness. Re-fitted at the four quarter turns,
grown about the photo's centroid, the creature is found; scenes of benchmarks/accuracy.py with its seeds."""

from __future__ import annotations

import dataclasses

import numpy as np
from _bench_scenes import found_within_5, renderer_scene

from photoservo.config import load_config
from photoservo.vision.candidates import grown_about_centroid
from photoservo.vision.estimator import estimate
from photoservo.vision.twins import mask_centroid_mm

CFG = load_config()
P = CFG.estimator


def test_a_squid_fitted_shrunk_and_turned_is_found_regrown():
    # benchmarks/accuracy.py --first-scene 200: scene 240 (seed 1240), a squid, its own photo; the island
    # ends 31 % too small, turned 20 deg, 3.0 % off: outline 0.21 and two parts absent, one on bare water
    sc, model = renderer_scene(1240, kind="squid")
    found_within_5(sc, model, seed=240)
    without = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, dataclasses.replace(P, grown_turns=False),
                       CFG.fitness, seed=240)
    assert not without.found


def test_a_split_crab_fitted_shrunk_and_turned_a_quarter_is_found_regrown():
    # --first-scene 1100: scene 1138 (seed 2138), a crab across a foam band, its own photo; the island ends
    # 27 % too small and turned 92 deg, 2.4 % off, 4 of 12 parts absent; re-fitted a quarter turn back
    # and grown 1.35 x it passes at the candidate's fitness (within one point's weight)
    sc, model = renderer_scene(2138, kind="crab", split=True)
    found_within_5(sc, model, seed=1138)


def test_grown_about_centroid_keeps_the_centroid_in_place():
    sc, model = renderer_scene(1240, kind="squid")
    R = np.array(sc.truth["rotation"])
    t = np.array(sc.truth["position_mm"])
    a = float(sc.truth["alpha_px_per_mm"])
    t2, a2 = grown_about_centroid(R, t, a, model, 1.35)
    assert a2 == a / 1.35
    assert np.allclose(R @ mask_centroid_mm(model, a2) + t2, R @ mask_centroid_mm(model, a) + t)
