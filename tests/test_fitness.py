"""Stereo fitness (method step 3): projection, scoring cases, kernel == numpy reference."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest
from _fitness_scene import ALPHA_TRUE, R_TRUE, T_TRUE, make_model, render_stereo, rot
from hypothesis import given, settings
from hypothesis import strategies as st

from photoservo.errors import InputError
from photoservo.config import load_config
from photoservo.vision.fitness import (
    IN_MATCH,
    OUTSIDE,
    StereoHue,
    counts_compiled,
    counts_reference,
    fitness,
    fitness_reference,
    project_model,
    projected,
    stereo_hue,
)
from photoservo.vision.photo_model import NO_HUE
from photoservo.vision.rig import Camera, Rig, default_rig

PARAMS = load_config().fitness
MODEL, PHOTO = make_model()
RIG = default_rig()
LEFT, RIGHT = render_stereo(PHOTO, MODEL, RIG, R_TRUE, T_TRUE, ALPHA_TRUE)
FRAME = stereo_hue(LEFT, RIGHT, PARAMS)


def distorted_rig() -> Rig:
    """A rig with real-looking distortion and a slightly rotated right camera."""
    K = np.array([[780.0, 0.0, 322.0], [0.0, 790.0, 236.0], [0.0, 0.0, 1.0]])
    left = Camera(size=(640, 480), K=K, dist=np.array([-0.21, 0.08, 0.001, -0.0005, -0.01]))
    right = Camera(size=(640, 480), K=K + np.diag([5.0, -3.0, 0.0]),
                   dist=np.array([-0.18, 0.05, -0.0008, 0.0004, 0.0, 0.01, -0.002, 0.003]))
    return Rig(left=left, right=right, R=rot("y", -2.0) @ rot("x", 0.3), T=np.array([-101.0, 0.8, 1.5]))


def population(n: int, seed: int, spread: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n poses scattered around the truth (spread 1 ~ 40 mm, 25 deg, x1.4 in alpha)."""
    rng = np.random.default_rng(seed)
    R = np.empty((n, 3, 3))
    for i in range(n):
        rvec = rng.normal(0, 0.25 * spread, 3)
        R[i] = cv2.Rodrigues(rvec)[0] @ R_TRUE
    t = T_TRUE + rng.normal(0, 40 * spread, (n, 3))
    alpha = ALPHA_TRUE * np.exp(rng.normal(0, 0.3 * spread, n))
    return R, t, alpha


# ------------------------------------------------------------------------ projection


def test_projection_equals_cv2_project_points():
    rig = distorted_rig()
    R, t, alpha = population(5, seed=1)
    p = project_model(R, t, alpha, MODEL, rig)
    for i in range(5):
        for uv, pts_px, cam, Rc, tc in [
            (p.inner_left[i], MODEL.inner_uv, rig.left, R[i], t[i]),
            (p.outer_right[i], MODEL.outer_uv, rig.right, rig.R @ R[i], rig.R @ t[i] + rig.T),
        ]:
            X = np.column_stack([pts_px / alpha[i], np.zeros(len(pts_px))])
            ref, _ = cv2.projectPoints(X, cv2.Rodrigues(Rc)[0], tc, cam.K, cam.dist)
            np.testing.assert_allclose(uv, ref.reshape(-1, 2), atol=1e-6)


def test_model_point_frame_convention():
    """A model point (u, v) px sits at (u/alpha, v/alpha, 0) mm: with R = I it lands at
    K · (t + (u, v, 0)/alpha), x right and y down as in the photo."""
    R, t, alpha = np.eye(3), np.array([0.0, 0.0, 500.0]), 2.0
    p = project_model(R, t, alpha, MODEL, RIG)
    f, cx, cy = RIG.left.K[0, 0], RIG.left.K[0, 2], RIG.left.K[1, 2]
    uv = MODEL.inner_uv
    np.testing.assert_allclose(p.inner_left[0], np.column_stack([cx + f * uv[:, 0] / 2 / 500,
                                                                 cy + f * uv[:, 1] / 2 / 500]))
    # the right camera sits +100 mm along x (T = -100): the model appears shifted left by f·B/z
    np.testing.assert_allclose(p.inner_right[0][:, 0], p.inner_left[0][:, 0] - f * 100 / 500)


# ------------------------------------------------------------------------ scoring


def test_truth_scores_one():
    assert fitness(R_TRUE, T_TRUE, ALPHA_TRUE, MODEL, FRAME, RIG, PARAMS)[0] == pytest.approx(1.0, abs=0.01)


@pytest.mark.parametrize(
    "what, R, t, alpha",
    [
        ("shift x 10 mm", R_TRUE, T_TRUE + [10, 0, 0], ALPHA_TRUE),
        ("shift y 10 mm", R_TRUE, T_TRUE + [0, 10, 0], ALPHA_TRUE),
        ("shift z 60 mm", R_TRUE, T_TRUE + [0, 0, 60], ALPHA_TRUE),
        ("roll 10 deg", rot("z", 10) @ R_TRUE, T_TRUE, ALPHA_TRUE),
        ("tilt 25 deg", rot("x", 25) @ R_TRUE, T_TRUE, ALPHA_TRUE),
        ("alpha x1.2, same distance", R_TRUE, T_TRUE, ALPHA_TRUE * 1.2),
        ("alpha /1.2, same distance", R_TRUE, T_TRUE, ALPHA_TRUE / 1.2),
    ],
)
def test_true_pose_outscores_perturbed(what, R, t, alpha):
    f_true = fitness(R_TRUE, T_TRUE, ALPHA_TRUE, MODEL, FRAME, RIG, PARAMS)[0]
    f_bad = fitness(R, np.asarray(t, float), alpha, MODEL, FRAME, RIG, PARAMS)[0]
    assert f_true > f_bad + 0.05, what


@pytest.mark.parametrize("k", [0.6, 0.8, 1.25, 1.6])
def test_stereo_separates_big_far_from_small_near(k):
    """t -> k·t with alpha -> alpha/k (a model k times bigger, k times farther) projects exactly
    alike in the left camera; only the right camera tells them apart."""
    counts = counts_reference(R_TRUE, T_TRUE * k, ALPHA_TRUE / k, MODEL, FRAME, RIG, PARAMS)[0]
    counts_true = counts_reference(R_TRUE, T_TRUE, ALPHA_TRUE, MODEL, FRAME, RIG, PARAMS)[0]
    np.testing.assert_array_equal(counts[0], counts_true[0])  # left: indistinguishable
    assert counts[1, IN_MATCH] < 0.8 * counts_true[1, IN_MATCH]  # right: not
    f_true = fitness(R_TRUE, T_TRUE, ALPHA_TRUE, MODEL, FRAME, RIG, PARAMS)[0]
    f_conf = fitness(R_TRUE, T_TRUE * k, ALPHA_TRUE / k, MODEL, FRAME, RIG, PARAMS)[0]
    assert f_true > f_conf + 0.1


def test_combine_modes_agree_on_perfect_and_rank_confusion_lower():
    k = 1.25
    for mode in ("mean", "min", "product"):
        p = dataclasses.replace(PARAMS, combine=mode)
        f = fitness(np.stack([R_TRUE] * 2), np.stack([T_TRUE, T_TRUE * k]), np.array([1.0, 1.0 / k]),
                    MODEL, FRAME, RIG, p)
        assert f[0] == pytest.approx(1.0, abs=0.01) and f[1] < f[0] - 0.1, mode


def test_no_hue_pixels_neither_reward_nor_punish():
    """Points landing on NO_HUE pixels contribute exactly 0: a frame with no hue anywhere
    scores 0 for every pose; glare over half of the target lowers the truth's score by exactly
    the share of points it hides, and costs a wrong pose nothing."""
    blank = np.full_like(FRAME.left, NO_HUE)
    R, t, alpha = population(12, seed=3)
    np.testing.assert_array_equal(fitness(R, t, alpha, MODEL, StereoHue(blank, blank), RIG, PARAMS), 0.0)

    glare_l, glare_r = LEFT.copy(), RIGHT.copy()
    glare_l[:, :360] = (255, 255, 255)  # white: saturation 0
    glare_r[:, :360] = (10, 10, 10)  # dark: value below the floor
    frame = stereo_hue(glare_l, glare_r, PARAMS)
    assert np.all(frame.left[:, :360] == NO_HUE) and np.all(frame.right[:, :360] == NO_HUE)
    c_glare = counts_reference(R_TRUE, T_TRUE, ALPHA_TRUE, MODEL, frame, RIG, PARAMS)[0]
    c_clear = counts_reference(R_TRUE, T_TRUE, ALPHA_TRUE, MODEL, FRAME, RIG, PARAMS)[0]
    n = len(MODEL.inner_uv) + len(MODEL.outer_uv)
    hidden = n - c_glare[:, :4].sum(axis=1)  # points on NO_HUE per camera
    assert np.all(hidden > 50)
    assert np.all(c_glare[:, 1] == 0) and np.all(c_glare[:, 3] == 0)  # no mismatch appears
    f = fitness(R_TRUE, T_TRUE, ALPHA_TRUE, MODEL, frame, RIG, PARAMS)[0]
    assert f == pytest.approx(1.0 - hidden.mean() / n)
    assert f < fitness(R_TRUE, T_TRUE, ALPHA_TRUE, MODEL, FRAME, RIG, PARAMS)[0]
    assert np.all(c_glare[:, :4].sum(axis=1) <= c_clear[:, :4].sum(axis=1))


def test_points_outside_the_image_or_behind_the_camera():
    n = len(MODEL.inner_uv) + len(MODEL.outer_uv)
    R = np.stack([R_TRUE] * 3)
    t = np.array([[5000.0, 0, 600], [0, 0, -600], [0, -1500, 600]])  # right of view, behind, above
    alpha = np.ones(3)
    counts = counts_reference(R, t, alpha, MODEL, FRAME, RIG, PARAMS)
    np.testing.assert_array_equal(counts[:, :, OUTSIDE], n)
    np.testing.assert_array_equal(fitness(R, t, alpha, MODEL, FRAME, RIG, PARAMS), 0.0)
    p = dataclasses.replace(PARAMS, w_outside=0.5)
    np.testing.assert_allclose(fitness(R, t, alpha, MODEL, FRAME, RIG, p), -0.5)
    # partly outside: the target cut by the left image border keeps only what is in view
    t_edge = T_TRUE + [-245.0, 0, 0]
    c = counts_reference(R_TRUE, t_edge, ALPHA_TRUE, MODEL, FRAME, RIG, PARAMS)[0, 0]
    assert 0 < c[OUTSIDE] < n


def test_config_validation_names_the_key():
    with pytest.raises(InputError, match="fitness.hue_tolerance"):
        load_config(overrides=["fitness.hue_tolerance=120"])
    with pytest.raises(InputError, match="fitness.w_outside"):
        load_config(overrides=["fitness.w_outside=-1"])
    with pytest.raises(InputError, match="fitness.combine"):
        load_config(overrides=["fitness.combine=sum"])


# ------------------------------------------------------------------------ compiled kernel


@pytest.mark.parametrize("rig_name", ["ideal", "distorted"])
@pytest.mark.parametrize("kernel", ["numba", "numba-parallel"])
def test_kernel_equals_numpy_reference(rig_name, kernel):
    rig = RIG if rig_name == "ideal" else distorted_rig()
    p = dataclasses.replace(PARAMS, kernel=kernel, w_outside=0.3)
    for seed, spread in [(10, 0.3), (11, 1.0), (12, 4.0)]:
        R, t, alpha = population(40, seed, spread)
        t[::7, 2] *= -1  # some behind the camera
        np.testing.assert_array_equal(counts_compiled(R, t, alpha, MODEL, FRAME, rig, p),
                                      counts_reference(R, t, alpha, MODEL, FRAME, rig, p))
        for mode in ("mean", "min", "product"):
            q = dataclasses.replace(p, combine=mode)
            np.testing.assert_allclose(fitness(R, t, alpha, MODEL, FRAME, rig, q),
                                       fitness_reference(R, t, alpha, MODEL, FRAME, rig, q), atol=1e-12)


def test_kernel_degenerate_poses_equal_reference():
    """Model planes through or next to the camera centre: points overflow to inf/NaN in the
    projection and must count as outside in both implementations (a fastmath kernel got this
    wrong; found by the hypothesis test below)."""
    rig = distorted_rig()
    R = np.stack([rot("y", 57.3), rot("x", 89.9), rot("y", 90.0), np.eye(3), rot("x", 30.0)])
    t = np.array([[0.0, 0.0, 1e-171], [0.0, 0.0, 0.0], [0.0, 0.0, 1e-3], [0.0, 0.0, 1e-9], [0.0, 0.0, 5.0]])
    alpha = np.array([1.0, 1.0, 1e-6, 1e6, 1e-3])
    np.testing.assert_array_equal(counts_compiled(R, t, alpha, MODEL, FRAME, rig, PARAMS),
                                  counts_reference(R, t, alpha, MODEL, FRAME, rig, PARAMS))


def test_kernel_reads_the_right_pixels():
    """A hue image with a distinct code per pixel region: the kernel and the reference must
    agree point by point, not only in total (a transposed index would not)."""
    rng = np.random.default_rng(5)
    hue = rng.integers(0, 180, FRAME.left.shape).astype(np.uint8)
    hue[rng.random(hue.shape) < 0.2] = NO_HUE
    frame = StereoHue(hue, np.ascontiguousarray(hue[::-1]))
    R, t, alpha = population(25, seed=6, spread=2.0)
    p = dataclasses.replace(PARAMS, kernel="numba")
    np.testing.assert_array_equal(counts_compiled(R, t, alpha, MODEL, frame, RIG, p),
                                  counts_reference(R, t, alpha, MODEL, frame, RIG, p))


@pytest.mark.parametrize("kernel", ["numba", "numba-parallel", "numpy"])
def test_empty_population_gives_empty_scores(kernel):
    """The GA may score only the valid part of a population, which can be empty."""
    p = dataclasses.replace(PARAMS, kernel=kernel)
    f = fitness(np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros(0), MODEL, FRAME, RIG, p)
    assert f.shape == (0,)


def test_bad_population_is_a_value_error():
    with pytest.raises(ValueError, match="alpha <= 0"):
        fitness(R_TRUE, T_TRUE, 0.0, MODEL, FRAME, RIG, PARAMS)
    with pytest.raises(ValueError, match="non-finite"):
        fitness(R_TRUE, T_TRUE * np.nan, 1.0, MODEL, FRAME, RIG, PARAMS)
    with pytest.raises(ValueError, match="shapes"):
        fitness(np.stack([R_TRUE] * 2), T_TRUE, [1.0, 1.0], MODEL, FRAME, RIG, PARAMS)


# ------------------------------------------------------------------------ properties

poses = st.tuples(
    st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),  # rotation vector (rad)
    st.lists(st.floats(-800.0, 800.0), min_size=2, max_size=2),  # x, y (mm)
    st.floats(-200.0, 3000.0),  # z (mm), sometimes behind the camera
    st.floats(-3.0, 3.0),  # log alpha
)


@settings(max_examples=60, deadline=None)
@given(pose=poses, combine=st.sampled_from(["mean", "min", "product"]), w_outside=st.floats(0.0, 1.0))
def test_fitness_bounded_by_one_and_by_the_costs(pose, combine, w_outside):
    rvec, xy, z, log_alpha = pose
    R = cv2.Rodrigues(np.array(rvec))[0]
    t = np.array([*xy, z])
    p = dataclasses.replace(PARAMS, combine=combine, w_outside=w_outside)
    f = fitness(R, t, np.exp(log_alpha), MODEL, FRAME, RIG, p)[0]
    worst = max(p.w_inner_mismatch, p.w_outer_mismatch, w_outside) * 1.0  # w_*_match are 1
    assert -worst - 1e-12 <= f <= 1.0 + 1e-12


@settings(max_examples=40, deadline=None)
@given(pose=poses)
def test_kernel_equals_reference_anywhere(pose):
    rvec, xy, z, log_alpha = pose
    R = cv2.Rodrigues(np.array(rvec))[0][None]
    t = np.array([[*xy, z]])
    alpha = np.array([np.exp(log_alpha)])
    rig = distorted_rig()
    np.testing.assert_array_equal(counts_compiled(R, t, alpha, MODEL, FRAME, rig, PARAMS),
                                  counts_reference(R, t, alpha, MODEL, FRAME, rig, PARAMS))


def test_projected_is_the_callers_projection_when_given_else_the_poses_own():
    """`projected`: a rule handed `detect`'s projection reads it as it is (the same object); without it, the
    pose's `project_model`, to the bit."""
    model, rig = make_model()[0], default_rig()
    own = project_model(R_TRUE, T_TRUE, ALPHA_TRUE, model, rig)
    assert projected(R_TRUE, T_TRUE, ALPHA_TRUE, model, rig, own) is own
    computed = projected(R_TRUE, T_TRUE, ALPHA_TRUE, model, rig, None)
    for f in ("inner_left", "inner_right", "outer_left", "outer_right"):
        assert np.array_equal(getattr(computed, f), getattr(own, f))
