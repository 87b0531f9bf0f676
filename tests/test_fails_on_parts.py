"""`Detection.fails_on_parts` (vision/detection.py): every test passes but the parts — what
`candidates.parted_turns` re-fits turned, read from detect's own decision."""

from __future__ import annotations

import dataclasses

from _bench_scenes import candidate, harbour_scene

from photoservo.config import load_config
from photoservo.vision.detection import detect
from photoservo.vision.estimator import estimate
from photoservo.vision.fitness import stereo_hue

CFG = load_config()
P = CFG.estimator


def test_fails_on_parts_says_when_the_parts_alone_reject():
    # harbour look-alike null 1565 (a crab's model on a float, 3-4 of 12 parts absent, contrast and
    # outline passing): what `candidates.parted_turns` re-fits turned
    sc, model = harbour_scene(1565, kind="crab", empty=True, distractor=True)
    frame = stereo_hue(sc.left, sc.right, CFG.fitness)
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=65)
    c = candidate(est.candidates[0])
    d = detect(c, model, frame, sc.rig, CFG.fitness, P, seed=65)
    assert not d.passed and d.fails_on_parts and d.absent_parts > P.max_absent_parts
    lax = detect(c, model, frame, sc.rig, CFG.fitness, dataclasses.replace(P, max_absent_parts=1.0), seed=65)
    assert lax.passed and not lax.fails_on_parts
    strict = detect(c, model, frame, sc.rig, CFG.fitness, dataclasses.replace(P, min_contrast=1.5), seed=65)
    assert not strict.passed and not strict.fails_on_parts
