"""Another individual's photo (issue 9 item 4, the other-photo size): what the benchmark's truth
makes of its size, and what the hue fitness sees of its proportions (docs/notes/estimation.md,
'Another individual's size: where the error comes from')."""

from __future__ import annotations

import math

import numpy as np
import pytest

from photoservo.config import load_config
from photoservo.sim import harbour
from photoservo.sim.scenes import EFFECTS, match_individuals, random_scene
from photoservo.vision.fitness import fitness, stereo_hue
from photoservo.vision.photo_model import build_photo_model
from photoservo.vision.pose_search import aspect_map

CFG = load_config()


def shape_pct(truth: dict) -> float:
    """The size error of the estimator's photo at the truth's own alpha, one scale on both axes
    (benchmarks/accuracy.py `shape_pct`): the other individual's proportions alone."""
    return 100 * float(np.max(np.abs(np.divide(truth["size_mm"], truth["creature_size_mm"]) - 1)))


@pytest.mark.parametrize("kind, floor", [("squid", 11.0), ("crab", 4.1), ("fish", 7.4)])
def test_the_renderer_has_one_other_individual_per_kind(kind, floor):
    """The renderer's other photo is `specimen(kind, 0, other=True)` in every scene, so each kind's
    scenes share one shape error: a squid's box is 11 % off the creature's at the truth's (mask-area)
    alpha, whatever the scene."""
    for seed in (1001, 1013):
        sc = random_scene(seed, CFG.synthetic, CFG.photo_model, kind=kind, other_photo=True, effects=())
        assert shape_pct(sc.truth) == pytest.approx(floor, abs=0.1)
        same = random_scene(seed, CFG.synthetic, CFG.photo_model, kind=kind, effects=())
        assert shape_pct(same.truth) == pytest.approx(0.0, abs=1e-9)


def test_the_harbour_draws_another_individual_per_scene():
    """The harbour generator draws the other individual from the scene's seed: its shape error
    differs from scene to scene (squid 1105 9.7 %, 1111 8.7 %, 1117 4.2 %)."""
    got = [shape_pct(harbour.random_scene(seed, CFG.synthetic, CFG.photo_model, kind="squid", other_photo=True).truth)
           for seed in (1105, 1111, 1117)]
    assert got == pytest.approx([9.7, 8.7, 4.2], abs=0.1)


@pytest.mark.parametrize("seed, kind, box_minus_area", [(1047, "fish", (0.05, 0.13)), (1013, "crab", (-0.01, 0.01)),
                                                      (1039, "squid", (-0.06, -0.02))])
def test_the_hue_fitness_sees_a_fishs_proportions_not_a_squids_box(seed, kind, box_minus_area):
    """Renderer scenes 1047, 1013 and 1039 of benchmarks/accuracy.py (another individual's photo), at
    the truth pose: the fitness with the per-axis alpha that lays the photo's box onto the
    creature's box (centre on centre) against the truth's one alpha (mask area, centroids
    together). The fish's box scale fits better (0.82 against 0.73; all 10 tuned fish scenes
    +0.03..+0.09): the per-axis alpha can find it. The crab's scores alike (-0.003; the 5 crabs
    tried -0.003..+0.017): the fitness cannot tell its proportions. The squid's fits worse (0.75
    against 0.78; 9 of the 10 tuned squid scenes -0.02..-0.05, one alike): the other squid's fins
    spread wider for its body, so a fit that matches the body reports a box 11 % too tall, and the
    alpha the hue fitness prefers is not the one that reports the creature's box."""
    sc = random_scene(seed, CFG.synthetic, CFG.photo_model, kind=kind, other_photo=True, effects=tuple(EFFECTS),
                      distractor=True, split=False)
    model = build_photo_model(sc.photo, CFG.photo_model)
    frame = stereo_hue(sc.left, sc.right, CFG.fitness)
    t = sc.truth
    R, alpha = np.array(t["rotation"]), t["alpha_px_per_mm"]
    ax, ay = np.divide(model.size_px, t["creature_size_mm"])  # the photo's box onto the creature's
    model_A = build_photo_model(sc.render_photo, CFG.photo_model)
    _, origin_mm = match_individuals(model_A, model, model_A.size_px[0] / t["creature_size_mm"][0])
    box_centre = np.array(t["position_mm"]) - R @ origin_mm  # the creature's box centre: its model origin

    def f(position, a, k):
        return float(fitness(aspect_map(R, np.array([k])), np.asarray(position, float)[None], np.array([a]),
                             model, frame, sc.rig, CFG.fitness)[0])

    f_area = f(t["position_mm"], alpha, 1.0)
    f_box = f(box_centre, math.sqrt(ax * ay), math.sqrt(ay / ax))
    lo, hi = box_minus_area
    assert lo < f_box - f_area < hi, (f_area, f_box)
