"""The second scene generator (sim/harbour.py): determinism, ground truth that lands on the
creature in both images (same photo and another individual's), a foam band that really splits
the creature's hue region, the many-hued fish whose hues include the water's, and
`photoservo synth --generator harbour`."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from test_synthetic import half_rig

from photoservo.cli.main import main
from photoservo.config import load_config
from photoservo.sim.harbour import random_scene
from photoservo.vision.fitness import stereo_hue
from photoservo.vision.photo_model import HUE_BINS, build_photo_model, hue_image
from photoservo.vision.rig import project_points

CFG = load_config()
RIG = half_rig()  # 320 x 240: a quarter of the rendering time


def truth_pixels(sc, model, uv: np.ndarray, right: bool, R=None, t=None) -> np.ndarray:
    """Pixels (N, 2) of photo-model points `uv` (px from the origin) at the truth pose (or R, t)
    in the left or right image of the rendering rig."""
    tr = sc.truth
    R = np.array(tr["rotation"]) if R is None else R
    t = np.array(tr["position_mm"]) if t is None else t
    X = np.column_stack([uv / tr["alpha_px_per_mm"], np.zeros(len(uv))]) @ R.T + t
    cam = sc.rig_true.left
    if right:
        X = X @ sc.rig_true.R.T + sc.rig_true.T
        cam = sc.rig_true.right
    return project_points(X, cam)


def on_creature(sc, px: np.ndarray, right: bool) -> np.ndarray:
    cov = sc.scene.coverage[1 if right else 0]
    ij = np.rint(px).astype(int)
    H, W = cov.shape
    ok = (ij[:, 0] >= 0) & (ij[:, 0] < W) & (ij[:, 1] >= 0) & (ij[:, 1] < H)
    out = np.zeros(len(px), bool)
    out[ok] = cov[ij[ok, 1], ij[ok, 0]] > 0.5
    return out


def test_same_seed_same_scene_other_seed_other_scene():
    a = random_scene(3, CFG.synthetic, CFG.photo_model, kind="crab", distractor=True, rig=RIG)
    b = random_scene(3, CFG.synthetic, CFG.photo_model, kind="crab", distractor=True, rig=RIG)
    c = random_scene(4, CFG.synthetic, CFG.photo_model, kind="crab", distractor=True, rig=RIG)
    assert np.array_equal(a.left, b.left) and np.array_equal(a.right, b.right)
    assert np.array_equal(a.photo, b.photo)
    assert a.truth == b.truth
    assert not np.array_equal(a.left, c.left)
    assert a.truth["generator"] == "harbour" and len(a.truth["distractors"]) == 1


@pytest.mark.parametrize("kind,other", [("squid", False), ("fish", True)])
def test_truth_lands_on_the_creature_in_both_images(kind, other):
    sc = random_scene(11, CFG.synthetic, CFG.photo_model, kind=kind, other_photo=other, rig=RIG)
    model = build_photo_model(sc.photo, CFG.photo_model)
    tr = sc.truth
    assert tr["same_photo"] is (not other)
    visible = 1 - tr["foam_cover"]
    inner_need = (0.97 if not other else 0.85) * visible - 0.02
    for right in (False, True):
        inner = on_creature(sc, truth_pixels(sc, model, model.inner_uv, right), right)
        outer = on_creature(sc, truth_pixels(sc, model, model.outer_uv, right), right)
        assert inner.mean() >= inner_need, (right, inner.mean())
        assert outer.mean() <= (0.03 if not other else 0.15), (right, outer.mean())
        # a pose a fifth of the creature's length off does not: the test can fail
        t_off = np.array(tr["position_mm"]) + np.array(tr["rotation"])[:, 0] * 0.2 * tr["size_mm"][0]
        shifted = on_creature(sc, truth_pixels(sc, model, model.inner_uv, right, t=t_off), right)
        assert shifted.mean() < inner.mean() - 0.1
    # the model's photo px per mm matches the creature's real size
    assert tr["size_mm"][0] == pytest.approx(model.size_px[0] / tr["alpha_px_per_mm"])
    if not other:
        assert tr["size_mm"] == pytest.approx(tr["creature_size_mm"])


def target_hue_pieces(sc, model) -> np.ndarray:
    """Areas (px, largest first) of the connected target-hue regions over the creature in the left
    image (after the 5x5 closing the estimator's blob seeding uses)."""
    hue = stereo_hue(sc.left, sc.right, CFG.fitness).left
    lut = np.zeros(256, np.uint8)
    lut[:HUE_BINS] = model.target_hues * 255
    mask = cv2.morphologyEx(lut[hue], cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5)))
    px = truth_pixels(sc, model, np.vstack([model.inner_uv, model.outer_uv]), False)
    x0, y0 = np.floor(px.min(0)).astype(int)
    x1, y1 = np.ceil(px.max(0)).astype(int)
    region = np.zeros_like(mask)
    region[max(0, y0):y1, max(0, x0):x1] = mask[max(0, y0):y1, max(0, x0):x1]
    n, _, stats, _ = cv2.connectedComponentsWithStats(region, connectivity=8)
    return np.sort(stats[1:, cv2.CC_STAT_AREA])[::-1]


def test_foam_band_splits_the_creature_hue_region_in_two():
    split = random_scene(21, CFG.synthetic, CFG.photo_model, kind="fish", foam_split=True, rig=RIG)
    plain = random_scene(21, CFG.synthetic, CFG.photo_model, kind="fish", rig=RIG)
    model = build_photo_model(split.photo, CFG.photo_model)
    assert split.truth["foam_split"] and not plain.truth["foam_split"]
    pieces = target_hue_pieces(split, model)
    assert len(pieces) >= 2 and pieces[1] >= 0.15 * pieces[:2].sum(), pieces[:4]
    whole = target_hue_pieces(plain, model)
    assert whole[0] >= 0.8 * whole.sum(), whole[:4]
    assert 0.05 < split.truth["foam_cover"] < 0.4


def test_many_hued_fish_carries_the_water_hue():
    sc = random_scene(5, CFG.synthetic, CFG.photo_model, kind="fish", many_hued=True, rig=RIG)
    model = build_photo_model(sc.photo, CFG.photo_model)
    hue = hue_image(sc.left, CFG.fitness.min_saturation, CFG.fitness.min_value)
    water = hue[sc.scene.coverage[0] < 0.01]
    water = water[water < HUE_BINS]
    dominant = int(np.argmax(np.bincount(water, minlength=HUE_BINS)))
    assert model.target_hues[dominant], dominant
    assert model.target_hues.sum() >= 100  # blue, green, yellow, orange, magenta
    assert sc.truth["many_hued"]


def test_empty_water_has_no_target():
    sc = random_scene(6, CFG.synthetic, CFG.photo_model, kind="squid", empty=True, rig=RIG)
    assert sc.truth["found"] is False and sc.truth["position_mm"] is None
    assert sc.scene.coverage[0].max() == 0.0


def test_synth_cli_harbour(tmp_path, capsys):
    out = tmp_path / "scene"
    assert main(["synth", "--generator", "harbour", "--specimen", "fish", "--foam-split", "--seed", "2",
                 "--out", str(out)]) == 0
    truth = json.loads((out / "truth.json").read_text())
    assert truth["generator"] == "harbour" and truth["foam_split"] is True
    for f in ("left.png", "right.png", "photo.png", "rig.toml"):
        assert (out / f).stat().st_size > 0
    capsys.readouterr()
    assert main(["synth", "--generator", "harbour", "--specimen", "crab", "--many-hued", "--out", str(tmp_path / "x")]) == 2
    assert "--many-hued" in capsys.readouterr().err
    assert main(["synth", "--specimen", "crab", "--foam-split", "--out", str(tmp_path / "y")]) == 2
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()
