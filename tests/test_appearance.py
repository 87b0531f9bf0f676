"""The appearance cue (vision/appearance.py): the photo's grey at the inner points correlated with
the image's at a pose. Invariant to a gain and an offset of the image (a brighter, darker or
colour-cast copy scores the same); the creature turned head to tail about its middle scores
lower; the photo-model carries its grey samples."""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
import pytest

from photoservo.config import load_config
from photoservo.sim.scenes import random_scene
from photoservo.vision.appearance import (
    StereoGrey,
    appearance,
    correlation,
    detrended,
    stereo_grey,
)
from photoservo.vision.fitness import stereo_hue
from photoservo.vision.photo_model import build_photo_model
from photoservo.vision.sampling import photo_values, sampling_pitch
from photoservo.vision.twins import turned_about_centroid

CFG = load_config()


@pytest.fixture(scope="module")
def squid():
    """A squid on water (waves, glints, noise), same photo: (scene, photo-model, truth pose)."""
    sc = random_scene(21, CFG.synthetic, CFG.photo_model, kind="squid", effects=("waves", "glints", "noise"))
    model = build_photo_model(sc.photo, CFG.photo_model)
    tr = sc.truth
    return sc, model, (np.array(tr["rotation"]), np.array(tr["position_mm"]), float(tr["alpha_px_per_mm"]))


def score(sc, model, pose, left=None, right=None):
    left = sc.left if left is None else left
    right = sc.right if right is None else right
    return appearance(*pose, model, stereo_hue(left, right, CFG.fitness), stereo_grey(left, right), sc.rig)


def test_photo_model_carries_the_photos_grey_at_each_inner_point(squid):
    sc, model, _ = squid
    assert model.inner_value.shape == (len(model.inner_uv),)
    assert sampling_pitch(model.inner_uv) == pytest.approx(CFG.photo_model.interval_px)
    # the sample is the blurred photo's grey at the point: a flat photo gives its own level
    flat = np.full((60, 80, 3), 90, np.uint8)
    assert np.allclose(photo_values(flat, np.array([[10.0, 10.0], [40.5, 30.5]]), 4.0), 90.0)
    # ...of the photo blurred over half a pitch (sigma 2 px), read bilinearly
    g = cv2.GaussianBlur(cv2.cvtColor(sc.photo, cv2.COLOR_BGR2GRAY).astype(np.float32), (0, 0), 2.0)
    x, y = (model.inner_uv + model.origin_px).T
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    want = ((1 - fy) * ((1 - fx) * g[y0, x0] + fx * g[y0, x0 + 1])
            + fy * ((1 - fx) * g[y0 + 1, x0] + fx * g[y0 + 1, x0 + 1]))
    assert np.allclose(model.inner_value, want, atol=0.1)


def test_truth_correlates_and_the_turned_twin_scores_lower(squid):
    sc, model, (R, t, alpha) = squid
    a_true = score(sc, model, (R, t, alpha))
    R2, t2 = turned_about_centroid(R, t, alpha, model)
    a_turned = score(sc, model, (R2, t2, alpha))
    assert a_true > 0.3
    assert a_turned < a_true - 0.3


def test_gain_and_offset_of_the_grey_leave_the_score_unchanged(squid):
    sc, model, pose = squid
    frame = stereo_hue(sc.left, sc.right, CFG.fitness)
    g = stereo_grey(sc.left, sc.right)
    a = appearance(*pose, model, frame, g, sc.rig)
    g2 = StereoGrey(left=0.6 * g.left + 40.0, right=1.3 * g.right - 10.0)
    assert appearance(*pose, model, frame, g2, sc.rig) == pytest.approx(a, abs=1e-5)


@pytest.mark.parametrize("gain_bgr", [(0.7, 0.7, 0.7), (1.2, 1.2, 1.2), (0.8, 1.0, 1.2)],
                         ids=["darker", "brighter", "colour-cast"])
def test_a_brighter_darker_or_colour_cast_copy_scores_the_same(squid, gain_bgr):
    sc, model, pose = squid
    a = score(sc, model, pose)

    def cast(img):
        return np.clip(img * np.array(gain_bgr) + 8.0, 0, 255).astype(np.uint8)

    assert score(sc, model, pose, cast(sc.left), cast(sc.right)) == pytest.approx(a, abs=0.05)


def test_no_grey_samples_or_no_view_gives_nan(squid):
    sc, model, (R, t, alpha) = squid
    bare = dataclasses.replace(model, inner_value=np.zeros(0, np.float32))
    assert math.isnan(score(sc, bare, (R, t, alpha)))
    assert math.isnan(score(sc, model, (R, t + np.array([5000.0, 0.0, 0.0]), alpha)))
    assert math.isnan(correlation(np.ones(5), np.arange(5.0)))


def test_a_brightness_gradient_across_the_creature_is_left_out():
    """The layout less its plane over the model offsets: a light's gradient (a + b u + c v) added
    to the samples leaves them as they were."""
    rng = np.random.default_rng(3)
    uv = rng.uniform(-50, 50, (200, 2))
    g = rng.normal(100, 20, 200)
    lit = g + 30.0 + 0.8 * uv[:, 0] - 0.5 * uv[:, 1]
    assert np.allclose(detrended(lit, uv), detrended(g, uv))
    assert abs(float(np.mean(detrended(g, uv)))) < 1e-9
