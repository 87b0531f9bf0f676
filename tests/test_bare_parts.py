"""Detection's bare-water check (vision/bare_parts.py): of two or more absent parts none may lie on
bare water. A float of the creature's one hue under a squid's model fitted small onto it leaves the
model's arms on the water's own colour (harbour null 1663: found before the check); a true squid
whose thin arms blur into the water keeps a trace of the body's colour there (harbour 1018, same
photo, 2 of 12 parts absent) and is still found."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from _bench_scenes import candidate, found_within_5, harbour_scene
from photoservo.config import load_config
from photoservo.sim.scenes import EFFECTS, random_scene
from photoservo.vision.appearance import stereo_grey
from photoservo.vision.bare_parts import bare_counts, bare_flags
from photoservo.vision.contour import stereo_chroma
from photoservo.vision.estimator import estimate
from photoservo.vision.fitness import inner_hues, project_model, stereo_hue
from photoservo.vision.parts import absent_flags, absent_share, model_parts
from photoservo.vision.photo_model import HUE_BINS, build_photo_model

CFG = load_config()
P = CFG.estimator


def _looks(sc):
    return stereo_hue(sc.left, sc.right, CFG.fitness), stereo_grey(sc.left, sc.right), stereo_chroma(sc.left, sc.right)


def test_absent_flags_are_the_parts_absent_share_counts():
    labels = np.repeat(np.arange(4), 10)
    hued = np.ones((2, 40), bool)
    on = np.ones((2, 40), bool)
    on[1, labels == 3] = False  # one part on the water's hue in the right camera
    hued[:, labels == 2] = False  # one under foam: not counted, not absent
    flags = absent_flags(hued, on & hued, labels)
    assert flags.tolist() == [[False] * 4, [False, False, False, True]]
    assert absent_share(hued, on & hued, labels) == flags.sum(axis=1).max() / 4


def test_parts_painted_over_with_the_water_are_bare_and_blurred_arms_are_not():
    # renderer 1000 (a squid, same photo) at its true pose: its thin arm tips blur into the water
    # (absent in both cameras, but a trace of the body's colour: not bare); two of its body's
    # parts painted over with the water's median colour are absent and bare
    sc = random_scene(1000, CFG.synthetic, CFG.photo_model, kind="squid", effects=EFFECTS)
    model = build_photo_model(sc.photo, CFG.photo_model)
    frame, grey, chroma = _looks(sc)
    labels = model_parts(model.inner_uv)
    tr = sc.truth
    R, t, alpha = np.array(tr["rotation"]), np.array(tr["position_mm"]), tr["alpha_px_per_mm"]
    absent, bare = bare_flags(R, t, alpha, model, frame, grey, chroma, sc.rig, labels)
    arms = absent[0] & absent[1]
    assert 1 <= arms.sum() <= 2 and not bare.any()
    body = [k for k in range(labels.max() + 1) if not absent[:, k].any()][:2]
    p = project_model(R, t, alpha, model, sc.rig)
    images = []
    for img, uv_in, uv_out, hue in ((sc.left, p.inner_left[0], p.outer_left[0], frame.left),
                                    (sc.right, p.inner_right[0], p.outer_right[0], frame.right)):
        img = img.copy()
        c = np.round(uv_out).astype(int)
        water = img[c[:, 1], c[:, 0]][~model.target_hues[np.minimum(hue[c[:, 1], c[:, 0]], HUE_BINS - 1)]]
        colour = tuple(int(v) for v in np.median(water, axis=0))
        for u, v in np.round(uv_in[np.isin(labels, body)]).astype(int):
            cv2.circle(img, (int(u), int(v)), 2, colour, -1)
        images.append(img)
    painted = dataclasses.replace(sc, left=images[0], right=images[1])
    frame, grey, chroma = _looks(painted)
    absent, bare = bare_flags(R, t, alpha, model, frame, grey, chroma, sc.rig, labels)
    assert absent[:, body].all() and bare[body].all()
    assert not bare[arms].any()
    n_absent, n_bare, _ = bare_counts(R, t, alpha, model, frame, grey, chroma, sc.rig, labels)
    assert n_absent == arms.sum() + 2 and n_bare == 2


def test_a_float_under_a_squid_model_is_not_found_for_its_arms_on_bare_water():
    # harbour null 1663 (benchmarks/accuracy.py --generator harbour --first-null 100): empty water
    # and an orange float; the squid's model fitted small onto the float, arms on water
    sc, model = harbour_scene(1663, kind="squid", empty=True, distractor=True)
    assert [d["kind"] for d in sc.truth["distractors"]] == ["float"]
    off = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, dataclasses.replace(P, bare_water_z=0.0), CFG.fitness,
                   seed=163)
    assert off.found  # what the check takes away: 2 of 12 parts absent, contrast ~0.68
    on = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=163)
    assert not on.found
    first = on.candidates[0]
    assert first["absent_parts"] == pytest.approx(2 / 12, abs=1e-3) and first["bare_parts"] >= 1
    assert first["contrast"] >= P.min_contrast and first["outer_on_target"] <= P.max_outer_on_target


@pytest.mark.parametrize("seed, distractor", [(2209, "float"), (2221, "species"), (2275, "species")])
def test_a_part_one_camera_sees_does_not_excuse_a_look_alike(seed, distractor):
    # harbour held-out 5 nulls (benchmarks/accuracy.py --generator harbour --first-null 700): a float
    # and another species under a squid's model, 2 of 12 parts absent, one of them in one camera
    # only. Counting only the parts both cameras miss (Dec 1, reverted) found them both. 2275: another
    # species under a squid's model, both arm parts on bare water; its layout holds both appearance cues
    # (0.29, 0.54), which excuse ONE part on bare water, not two (found when they excused any number)
    sc, model = harbour_scene(seed, kind="squid", empty=True, distractor=True)
    assert [d["kind"] for d in sc.truth["distractors"]] == [distractor]
    est = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, P, CFG.fitness, seed=seed - 1500)
    assert not est.found


def test_a_squid_whose_thin_arms_blur_into_the_water_keeps_them():
    # harbour 1018 (same photo, split by foam): two arm parts absent, their pixels half way from the
    # water's colour to the body's; found as before
    sc, model = harbour_scene(1018, kind="squid", foam_split=True)
    est = found_within_5(sc, model, seed=18)
    c = candidate(est.candidates[0])
    frame, grey, chroma = _looks(sc)
    labels = model_parts(model.inner_uv)
    n_absent, bare, _ = bare_counts(c.R_model, c.position_mm, c.alpha, model, frame, grey, chroma, sc.rig,
                                    labels)
    assert n_absent == 2 and bare == 0
    # the absent parts land off the target's hues in at least one camera: the check judged them
    h = inner_hues(c.R_model, c.position_mm, c.alpha, model, frame, sc.rig)
    assert (h < HUE_BINS).mean() > 0.5


def test_another_individuals_squid_with_the_photos_layout_keeps_an_arm_on_bare_water():
    # harbour 1453 (benchmarks/accuracy.py --generator harbour --first-scene 400): another individual's
    # squid whose tentacle lies elsewhere than the photo's. Its fit 1.1 % off has that arm's part on bare
    # water and a second arm part absent: the bare-water rule's pattern, as a float's. Inside, the
    # brightness layout is the photo's by both appearance cues (a float of one hue has none to show):
    # found. With the layout not counted (min_appearance above every cue) the rule rejects it
    sc, model = harbour_scene(1453, kind="squid", other_photo=True)
    est = found_within_5(sc, model, seed=453)
    first = est.candidates[0]
    assert first["absent_parts"] == pytest.approx(2 / 12, abs=1e-3) and first["bare_parts"] >= 1
    assert min(first["appearance"], first["body_layout"]) >= P.min_appearance
    blind = estimate(model, sc.left, sc.right, sc.rig, CFG.ga, dataclasses.replace(P, min_appearance=1.01),
                     CFG.fitness, seed=453)
    assert not blind.found


def test_the_rules_read_the_same_on_the_projection_detection_passes():
    # detection projects a candidate once (fitness.project_model) for the parts check and every rule of
    # vision/bare_parts.py; each rule given that projection reads exactly what it reads projecting the pose
    # itself (renderer 1000, a squid at its true pose and 8 % nearer)
    from photoservo.vision.appearance import stereo_saturation, stereo_value
    from photoservo.vision.bare_parts import body_gap, body_purity, body_relief, off_water
    from photoservo.vision.parts import absent_parts

    sc = random_scene(1000, CFG.synthetic, CFG.photo_model, kind="squid", effects=EFFECTS)
    model = build_photo_model(sc.photo, CFG.photo_model)
    frame, grey, chroma = _looks(sc)
    value, sat = stereo_value(sc.left, sc.right), stereo_saturation(sc.left, sc.right)
    labels = model_parts(model.inner_uv)
    tr = sc.truth
    R, alpha = np.array(tr["rotation"]), tr["alpha_px_per_mm"]
    for t in (np.array(tr["position_mm"]), 0.92 * np.array(tr["position_mm"])):
        proj = project_model(R, t, alpha, model, sc.rig)
        pose = (R, t, alpha, model, frame)
        assert bare_counts(*pose, grey, chroma, sc.rig, labels, proj=proj) == bare_counts(*pose, grey, chroma, sc.rig, labels)
        for got, own in ((off_water(*pose, chroma, sc.rig, CFG.fitness.contour_chroma, proj=proj),
                          off_water(*pose, chroma, sc.rig, CFG.fitness.contour_chroma)),
                         (body_gap(*pose, chroma, sc.rig, proj), body_gap(*pose, chroma, sc.rig)),
                         (body_relief(*pose, value, sc.rig, proj), body_relief(*pose, value, sc.rig)),
                         (body_purity(*pose, sat, sc.rig, proj), body_purity(*pose, sat, sc.rig)),
                         (absent_parts(*pose, sc.rig, labels, proj=proj), absent_parts(*pose, sc.rig, labels))):
            assert np.array_equal(got, own, equal_nan=True)
