"""The second real pair (sim/middlebury.py "aloe": Middlebury 2006 Aloe as Debian's opencv-doc
ships it), at half size: where its files are absent (the CI) every test but the first skips,
naming the file and how to get it; where present, the rig's conventions against the ground-truth
disparity and ground truth that lands on the target in both images. The motorcycle pair
(tests/test_real_pair.py) stays the CI's real-pair case."""

from __future__ import annotations

import numpy as np
import pytest

from photoservo.config import load_config
from photoservo.errors import InputError
from photoservo.sim.middlebury import (
    ALOE,
    ALOE_ENV,
    aloe_missing,
    depth_from_disparity,
    pair_rig,
    real_cases,
    right_disparity,
    stereo_pair,
    surface_region,
)
from photoservo.vision.rig import project_points

CFG = load_config(None, ["estimator.z_min_mm=500", "estimator.z_max_mm=5000"])
SCALE = 0.5
needs_aloe = pytest.mark.skipif(aloe_missing() is not None, reason=aloe_missing() or "")


def test_without_the_files_one_line_names_the_missing_file(tmp_path, monkeypatch):
    """No data: an InputError (exit status 2) whose one line names the file and how to get it."""
    monkeypatch.setenv(ALOE_ENV, str(tmp_path))
    with pytest.raises(InputError) as e:
        real_cases(CFG.photo_model, scale=SCALE, pair="aloe")
    msg = str(e.value)
    assert "\n" not in msg and str(tmp_path / "aloeL.jpg") in msg
    assert "apt-get download opencv-doc" in msg and "dpkg-deb -x" in msg and ALOE_ENV in msg


@pytest.fixture(scope="module")
def cases():
    return real_cases(CFG.photo_model, scale=SCALE, pair="aloe")


@needs_aloe
def test_rig_reprojects_the_ground_truth_disparity():
    """A left pixel at its depth (f B / (d + dmin)) projects into the right image at x - d, same row;
    the images are views 1 and 5 at full size (the disparity matches them photometrically)."""
    left, right, disp = stereo_pair(ALOE, SCALE)
    rig = pair_rig(ALOE, SCALE)
    assert (rig.left.width, rig.left.height) == (left.shape[1], left.shape[0]) == (641, 555)
    rng = np.random.default_rng(0)
    yx = np.argwhere(np.isfinite(disp))[rng.choice(int(np.isfinite(disp).sum()), 200, replace=False)]
    d = disp[yx[:, 0], yx[:, 1]].astype(float)
    pix = np.column_stack([yx[:, 1], yx[:, 0], np.ones(len(yx))])  # (u, v, 1) in the left image
    X = (pix @ np.linalg.inv(rig.left.K).T) * depth_from_disparity(d, SCALE, ALOE)[:, None]
    assert np.allclose(project_points(X @ rig.R.T + rig.T, rig.right), pix[:, :2] - np.column_stack([d, 0 * d]),
                       atol=1e-3)
    # grey levels agree at x - d (JPEG and lighting aside) and not at x + d
    gl, gr = (im.mean(axis=2) for im in (left, right))
    ok = np.isfinite(disp)
    ys, xs = np.nonzero(ok)
    for sign, lo, hi in ((-1, 0, 12), (1, 20, 255)):
        xr = np.rint(xs + sign * disp[ys, xs]).astype(int)
        inside = (xr >= 0) & (xr < disp.shape[1])
        err = np.abs(gl[ys[inside], xs[inside]] - gr[ys[inside], xr[inside]]).mean()
        assert lo <= err < hi, (sign, err)
    # forward warping keeps the nearest surface
    dr = right_disparity(disp)
    yr, xr = np.nonzero(np.isfinite(dr))
    j = rng.choice(len(xr), 200, replace=False)
    xl = np.rint(xr[j] + dr[yr[j], xr[j]]).astype(int)
    assert np.nanmedian(np.abs(disp[yr[j], xl] - dr[yr[j], xr[j]])) < 0.6


@needs_aloe
def test_three_targets_three_variants_with_truth_on_the_target(cases):
    """Pot, leaf and upright leaf, each cut from the left image, the right one and the left at
    0.6x: the photo-model at its true pose lands on the target's region in both cameras; the
    same object has the same size from either photo (the right cut of the leaf lacks its tip,
    out of the right image's frame). The truth is frontal (R = I) at the median depth of the
    model's mask: depth, lateral position and size are measured against it, not tilt."""
    assert {(c.target, c.variant) for c in cases} == {(t, v) for t in ALOE.targets
                                                      for v in ("left", "right", "scaled")}
    left, right, disp = stereo_pair(ALOE, SCALE)
    disp_r = right_disparity(disp)
    for c in cases:
        tr = c.truth
        assert 1400 < tr["distance_mm"] < 1900  # under the assumed dmin (sim/middlebury.py)
        X = np.column_stack([c.model.inner_uv / tr["alpha_px_per_mm"], np.zeros(len(c.model.inner_uv))]) \
            + np.array(tr["position_mm"])
        t = ALOE.targets[c.target]
        for cam, Xc, img, d in ((c.rig.left, X, left, disp), (c.rig.right, X @ c.rig.R.T + c.rig.T, right, disp_r)):
            uv = np.rint(project_points(Xc, cam)).astype(int)
            x, y, w, h = tr["box_px"]
            sx, sy = round(t.seed[0] * SCALE), round(t.seed[1] * SCALE)
            if cam is c.rig.right:
                dd = float(disp[sy, sx])
                x, sx = round(x - dd), round(sx - dd)
            region = surface_region(img, d, (x - 4, y - 4, w + 8, h + 8), (sx, sy), t.hues)
            on = region[np.clip(uv[:, 1], 0, img.shape[0] - 1), np.clip(uv[:, 0], 0, img.shape[1] - 1)]
            own = (cam is c.rig.right) == (c.variant == "right")
            # in the other camera the flat, frontal truth misses part of a thin leaf that leans in
            # depth (the upright leaf spans 1.65-1.75 m: 73 % of its points on it)
            assert on.mean() > (0.9 if own else 0.7), (c.target, c.variant, cam is c.rig.right, on.mean())
    by = {(c.target, c.variant): max(c.truth["size_mm"]) for c in cases}
    for t in ALOE.targets:
        assert by[(t, "scaled")] == pytest.approx(by[(t, "left")], rel=0.05)
        # the pot from the right: the dry leaf hanging in front of its rim stands 10 px further out
        assert by[(t, "right")] == pytest.approx(by[(t, "left")], rel=0.08)


@needs_aloe
def test_the_pot_is_seeded_at_its_size():
    """The terracotta pot cut from the left image: its hues fill most of the backdrop's motifs, so
    seeds come from the hue layout (vision/hue_layout.py). A 30-px box inside the pot agrees best
    and every layout peak lies on one (the pot 142 px; an island's window reaches 2x above its
    seed: every fit 3-8x too small). The peaks stay as they were, and the grown boxes (the largest
    side agreeing as well nearby) seed islands of their own: one at the pot's depth whose window
    reaches its size. Seed 1 from the default volume (depth 0.5-5 m): found, at its depth and size."""
    from photoservo.vision.estimator import estimate
    from photoservo.vision.fitness import stereo_hue
    from photoservo.vision.hue_layout import layout_pairs
    from photoservo.vision.seeding import ModelShape

    c, = real_cases(CFG.photo_model, scale=SCALE, targets=("pot",), variants=("left",), pair="aloe")
    tr, shape = c.truth, ModelShape.of(c.model)
    frame = stereo_hue(c.left, c.right, CFG.fitness)
    pairs, grown = layout_pairs(frame.left, frame.right, c.model, shape.area, c.rig, CFG.estimator)
    # the pot's apparent side in the left image: the model's side at the true scale (f / Z px per mm
    # in the image over alpha px per mm in the photo)
    side = np.sqrt(shape.area) * c.rig.left.K[0, 0] / tr["distance_mm"] / tr["alpha_px_per_mm"]
    assert 135 < side < 150
    assert pairs and all(np.sqrt(bp.left.area) < 0.25 * side for bp in pairs)
    assert any(abs(bp.position_mm[2] / tr["distance_mm"] - 1) < 0.05 and 2 * np.sqrt(bp.left.area) > side
               for bp in grown)
    est = estimate(c.model, c.left, c.right, c.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=1)
    assert est.found
    assert abs(est.position_mm[2] / tr["distance_mm"] - 1) < 0.05
    assert abs(tr["alpha_px_per_mm"] / est.alpha_px_per_mm - 1) < 0.15


@needs_aloe
@pytest.mark.parametrize("seed", [3, 4])
def test_the_pot_from_the_left_image_is_found_by_its_grown_island_refined(seed):
    """The pot cut from the left image, seeds 3 and 4: the grown boxes' islands end on the flank of the
    pot's peak (0.68-0.74), below the lead's small fit inside the pot (0.74, 72-80 % small), so the
    grown island was not refined and its fit was no candidate. A grown island larger in the images than
    the lead by more than the lead's own grown fits reach (contour_grow) is refined as the lead is
    (0.85-0.86 at 1.5-4.7 % in size): found, at the pot's depth and size, from a grown island."""
    from photoservo.vision.estimator import estimate

    c, = real_cases(CFG.photo_model, scale=SCALE, targets=("pot",), variants=("left",), pair="aloe")
    tr = c.truth
    est = estimate(c.model, c.left, c.right, c.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=seed)
    assert est.found
    assert est.candidates[0]["source"].startswith("grown")
    assert abs(est.position_mm[2] / tr["distance_mm"] - 1) < 0.05
    assert abs(tr["alpha_px_per_mm"] / est.alpha_px_per_mm - 1) < 0.15


@needs_aloe
def test_the_upright_leaf_at_0_6x_is_not_found_on_a_neighbouring_leaf():
    """The upright leaf cut at 0.6x, seed 1: its best candidate is a fit a third of its size on a
    neighbouring leaf's tip (0.53 where the standing's null, the model at that apparent size anywhere
    in the volume, reaches 0.55 on the plant: standing -0.04). It was 'found' there; a candidate
    standing at or below 0 does not pass (vision/detection.py), and no candidate on another object
    is found."""
    from photoservo.vision.estimator import estimate

    c, = real_cases(CFG.photo_model, scale=SCALE, targets=("upright",), variants=("scaled",), pair="aloe")
    est = estimate(c.model, c.left, c.right, c.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=1)
    assert not est.found
    best = est.candidates[0]
    assert best["standing"] <= 0 and best["contrast"] >= CFG.estimator.min_contrast
    x, y, w, h = c.truth["box_px"]
    uv = project_points(np.array(best["position_mm"]), c.rig.left)
    assert not (x <= uv[0] <= x + w and y <= uv[1] <= y + h)


@needs_aloe
def test_the_leaves_lie_on_the_photo_s_colours_and_the_neighbouring_leaf_does_not():
    """The photo's hue-saturation cells (vision/colour_cells.py; pixels down to saturation 12, where the
    leaves' hue mostly reads as none): at every true pose of the three targets the inner points lie on the
    photo's colours more often than the model's placements elsewhere at their 0.9 quantile (the leaves
    0.85-0.90 against <= 0.59; by hue they stand nowhere). The upright leaf at 0.6x, seed 0: its best
    candidate, a fit a third of its size on a neighbouring leaf's tip that stands just above the
    standing's null (0.02) and was found there, lies on them no more often than a placement elsewhere
    (0.43 against 0.66): not found."""
    from photoservo.vision.colour_cells import stereo_cells
    from photoservo.vision.detection import photo_colours
    from photoservo.vision.estimator import estimate
    from photoservo.vision.pose_search import Candidate

    for c in real_cases(CFG.photo_model, scale=SCALE, pair="aloe"):
        cells = stereo_cells(c.left, c.right, c.model.colour_cells, CFG.fitness.min_value)
        tr = c.truth
        own, null = photo_colours(Candidate(np.eye(3), np.array(tr["position_mm"]), tr["alpha_px_per_mm"], 0.0, 0,
                                            "truth"), c.model, cells, c.rig)
        assert own > null + 0.2, (c.target, c.variant, own, null)
    c, = real_cases(CFG.photo_model, scale=SCALE, targets=("upright",), variants=("scaled",), pair="aloe")
    est = estimate(c.model, c.left, c.right, c.rig, CFG.ga, CFG.estimator, CFG.fitness, seed=0)
    assert not est.found
    best = est.candidates[0]
    assert best["standing"] > 0 and best["contrast"] >= CFG.estimator.min_contrast
    x, y, w, h = c.truth["box_px"]
    uv = project_points(np.array(best["position_mm"]), c.rig.left)
    assert not (x <= uv[0] <= x + w and y <= uv[1] <= y + h)
