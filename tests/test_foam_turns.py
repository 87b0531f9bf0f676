"""A fit beside a foam band across a squid (`candidates.foam_turns`): the fitness scores a pixel without hue 0, so
where a band of foam crosses the creature a fit beside it, head to tail and off in depth, scores above the whole
creature and fails on parts the foam does not hide. Re-fitted at the four quarter turns by short GAs counting the
inner points on foam as matches (`PoseSearch`'s `foam`), a re-fit under the band passes; scenes of
benchmarks/accuracy.py with its seeds."""

from __future__ import annotations

import dataclasses

import numpy as np
from _bench_scenes import found_within_5, renderer_scene

from photoservo.config import load_config
from photoservo.vision.appearance import stereo_value
from photoservo.vision.estimator import estimate
from photoservo.vision.fitness import fitness, point_weight, stereo_hue
from photoservo.vision.parts import foam_marked, foam_share_inner, foam_shares
from photoservo.vision.pose_search import PoseSearch

CFG = load_config()
P = CFG.estimator


def test_a_split_squid_fitted_head_to_tail_beside_the_band_is_found_re_fitted_counting_foam():
    # benchmarks/accuracy.py --first-scene 1900: scene 1926 (seed 2926), a squid across a foam band, its own
    # photo; the island ends 4.7 % off, turned 172 deg and 26 % large, at 0.708 above the truth's 0.602 (a
    # quarter of the truth's inner points on foam), 3 parts absent, one on bare water. The half turn's re-fit
    # counting foam (0.774 so counted, against the candidate's 0.723) passes 1.6 % off
    sc, model = renderer_scene(2926, kind="squid", split=True)
    # the step is off in the config (configs/default.toml: it found renderer look-alike null 1853)
    assert not estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=1926).found
    found_within_5(sc, model, seed=1926, p=dataclasses.replace(P, foam_turns=True))


def test_the_foam_counted_search_scores_the_fitness_plus_the_points_on_foam():
    # the same scene's truth and two poses beside it: the population's foam shares are `foam_share_inner`'s,
    # and the search counting foam scores each pose's fitness plus one point's weight per inner point on
    # foam, the cameras' mean
    sc, model = renderer_scene(2926, kind="squid", split=True)
    frame = stereo_hue(sc.left, sc.right, CFG.fitness)
    value = stereo_value(sc.left, sc.right)
    foam = foam_marked(frame, value.left, value.right)
    R = np.repeat(np.array(sc.truth["rotation"])[None], 3, axis=0)
    t = np.array(sc.truth["position_mm"]) + np.array([[0.0, 0.0, 0.0], [20.0, 0.0, 0.0], [0.0, -30.0, 0.0]])
    a = np.full(3, float(sc.truth["alpha_px_per_mm"]))
    shares = foam_shares(R, t, a, model, foam, sc.rig)
    assert shares.shape == (3, 2) and np.all(shares[0] > 0.15)
    for k in range(3):
        assert np.array_equal(shares[k], foam_share_inner(R[k], t[k], a[k], model, foam, sc.rig))
    search = PoseSearch(model, sc.rig, frame, CFG.ga, P, CFG.fitness, np.random.default_rng(0), foam=foam)
    f = search._fitness(search.space.encode(R, t, a))
    plain = fitness(R, t, a, model, frame, sc.rig, CFG.fitness)
    w = point_weight(model, CFG.fitness)
    assert np.allclose(f, plain + w * len(model.inner_uv) * shares.mean(axis=1))
