"""Scenes as benchmarks/accuracy.py draws them (seed 1000 + i), and a candidate back from an estimate's
JSON, and an estimate found within 5 %, for the tests of detection's rules on benchmark scenes."""

from __future__ import annotations

import dataclasses

import numpy as np

from photoservo.config import load_config
from photoservo.sim import harbour
from photoservo.sim.scenes import EFFECTS, random_scene
from photoservo.vision.estimator import estimate
from photoservo.vision.photo_model import build_photo_model
from photoservo.vision.pose_search import Candidate

CFG = load_config()


def harbour_scene(seed, **kw):
    """A harbour scene as benchmarks/accuracy.py draws it, with its photo-model."""
    sc = harbour.random_scene(seed, CFG.synthetic, CFG.photo_model, **kw)
    return sc, build_photo_model(sc.photo, CFG.photo_model)


def renderer_scene(seed, **kw):
    """A renderer scene as benchmarks/accuracy.py draws it (every effect on), with its photo-model."""
    sc = random_scene(seed, CFG.synthetic, CFG.photo_model, effects=tuple(EFFECTS), **kw)
    return sc, build_photo_model(sc.photo, CFG.photo_model)


def found_within_5(sc, model, seed: int, p=None):
    """The estimate of scene `sc` with the benchmark's `seed` (estimator params `p`, default the config's),
    asserted found within 5 % of the distance; returned."""
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, CFG.estimator if p is None else p, CFG.fitness, seed=seed)
    assert est.found
    truth = np.array(sc.truth["position_mm"])
    assert np.linalg.norm(np.array(est.position_mm) - truth) / truth[2] < 0.05
    return est


def found_only_with(sc, model, seed: int, step: str):
    """`found_within_5` with the config's estimator, and not found with its switch `step` (an
    `EstimatorParams` bool, e.g. "grown_turns") off: the scene is found by that step."""
    found_within_5(sc, model, seed)
    without = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, dataclasses.replace(CFG.estimator, **{step: False}),
                       CFG.fitness, seed=seed)
    assert not without.found


def candidate(c: dict) -> Candidate:
    """The pose of a candidate of `Estimate.candidates` (its JSON) as a `Candidate`."""
    ax, ay = c["alpha_xy_px_per_mm"]
    return Candidate(np.array(c["rotation"]), np.array(c["position_mm"]), float(np.sqrt(ax * ay)), c["fitness"], 0,
                     "", aspect=float(np.sqrt(ay / ax)))
