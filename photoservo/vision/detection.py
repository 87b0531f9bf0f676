"""Detection (method step 3's fitness turned into a decision): is a candidate pose the creature?"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from photoservo.vision.fitness import OUT_MISMATCH, FitnessParams, StereoHue, counts_reference, fitness
from photoservo.vision.photo_model import PhotoModel
from photoservo.vision.pose_search import Candidate
from photoservo.vision.rig import Rig

if TYPE_CHECKING:
    from photoservo.vision.estimator import EstimatorParams


def confidence(f: float, params: EstimatorParams) -> float:
    """Logistic confidence that a candidate of fitness f is the target."""
    if not np.isfinite(f):
        return 0.0
    return 1.0 / (1.0 + math.exp(-(f - params.threshold) / params.confidence_scale))


@dataclass(frozen=True)
class Detection:
    """Is a candidate the target? `score`: the stereo fitness with the two cameras combined by
    their minimum (`[fitness] combine = "min"`), so a look-alike seen by one camera only, or a
    pose that fits one image and not the other, cannot pass on the strength of one camera (the GA
    itself optimises the configured combination). `outer_on_target`: the largest share, over the
    two cameras, of outer points S_out landing on target hue — the creature's outline must end
    where the model's does (a buoy or another species of the same colour usually spills over).
    passed = score >= threshold and outer_on_target <= max_outer_on_target;
    confidence = logistic((score - threshold) / confidence_scale)
                 · logistic((max_outer_on_target - outer_on_target) / 0.02)."""

    score: float
    outer_on_target: float
    passed: bool
    confidence: float


def detect(c: Candidate, model: PhotoModel, frame: StereoHue, rig: Rig, fit_params: FitnessParams,
           p: EstimatorParams) -> Detection:
    """The detection test of one candidate (see `Detection`)."""
    strict = dataclasses.replace(fit_params, combine="min")
    score = float(fitness(c.R, c.position_mm, c.alpha, model, frame, rig, strict)[0])
    counts = counts_reference(c.R, c.position_mm, c.alpha, model, frame, rig, fit_params)[0]
    outer = float(counts[:, OUT_MISMATCH].max()) / max(1, len(model.outer_uv))
    passed = score >= p.threshold and outer <= p.max_outer_on_target
    conf = confidence(score, p) / (1.0 + math.exp(-(p.max_outer_on_target - outer) / 0.02))
    return Detection(score=score, outer_on_target=outer, passed=bool(passed), confidence=conf)
