"""The renderer's fast path (render_view water_stride > 1, used by the live simulator): the target
lands where the exact render puts it with the same colours, the water keeps its mean colour and
its glints, the tiled sensor noise has the configured sigma, and renders are reproducible."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from photoservo.errors import InputError
from photoservo.config import load_config
from photoservo.vision.photo_model import NO_HUE, build_photo_model, hue_image
from photoservo.sim.renderer import (
    CameraEffects,
    Scene,
    StereoRenderer,
    _floater_layer,
    _lay_floater,
    _world_rays,
    coarse_rays,
    render_view,
)
from photoservo.sim.scenes import random_scene

CFG = load_config()
PM = CFG.photo_model


def target_hue_mask(img: np.ndarray, model) -> np.ndarray:
    hue = hue_image(img, PM.min_saturation, PM.min_value)
    return (hue != NO_HUE) & model.target_hues[np.minimum(hue, 179)]


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max(1, (a | b).sum()))


@pytest.fixture(scope="module", params=[(11, "squid", False), (12, "crab", True)])
def renders(request):
    """(exact (left, right), fast (left, right), estimator photo-model) at full resolution
    with waves, glints and noise; the second scene adds a look-alike and foam."""
    seed, kind, extra = request.param
    fx = ("waves", "glints", "noise", "foam") if extra else ("waves", "glints", "noise")
    sc = random_scene(seed, CFG.synthetic, PM, kind=kind, effects=fx, distractor=extra)
    r = StereoRenderer(sc.rig_true)
    effects = (CameraEffects(noise_sigma=CFG.synthetic.noise_sigma),) * 2
    exact = r.render(sc.scene, sc.T_world_left, 0.3, np.random.default_rng(1), effects)
    fast = r.render(sc.scene, sc.T_world_left, 0.3, np.random.default_rng(1), effects, water_stride=4)
    return exact, fast, build_photo_model(sc.photo, PM)


def test_fast_path_puts_the_target_where_the_exact_render_does(renders):
    exact, fast, model = renders
    for e, f in zip(exact, fast):
        me, mf = target_hue_mask(e, model), target_hue_mask(f, model)
        assert me.sum() > 500  # the target is in view...
        assert iou(me, mf) > 0.95, iou(me, mf)  # ...and covers the same pixels in both renders
        # creature colours at full resolution: equal up to noise and the water at its edge
        core = cv2.erode((me & mf).astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
        diff = np.abs(e[core].astype(float) - f[core].astype(float)).mean(axis=0)
        assert np.all(diff < 3.0), diff  # two N(0, 2) noises: 2.26 on average


def test_fast_path_keeps_the_waters_colour_and_glints(renders):
    exact, fast, model = renders
    for e, f in zip(exact, fast):
        # water: away from every floater and foam patch (pixels where the two renders differ a lot)
        objects = np.abs(e.astype(int) - f.astype(int)).max(axis=-1) > 60
        hue_e = hue_image(e, PM.min_saturation, PM.min_value)
        floaters = (hue_e == NO_HUE) | model.target_hues[np.minimum(hue_e, 179)] | objects
        water = ~cv2.dilate(floaters.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
        assert water.mean() > 0.5
        mean_e, mean_f = e[water].mean(axis=0), f[water].mean(axis=0)
        assert np.all(np.abs(mean_e - mean_f) < 3.0), (mean_e, mean_f)
        # texture kept: the fast water is not flat (its spread is most of the exact one's)
        assert f[water].std(axis=0).mean() > 0.6 * e[water].std(axis=0).mean()
        # glints present in both: near-white pixels, the fast render's count within 3x of the exact
        glint_e = (e.min(axis=-1) > 220).sum()
        glint_f = (f.min(axis=-1) > 220).sum()
        assert glint_e > 50 and glint_e / 3 < glint_f < 3 * glint_e, (glint_e, glint_f)


def test_fast_path_is_deterministic_and_its_noise_has_the_configured_sigma():
    sc = random_scene(13, CFG.synthetic, PM, kind="fish", effects=("waves",))
    r = StereoRenderer(sc.rig_true)
    wl = r.water_rays(4)[0]

    def view(rng, sigma):
        return render_view(sc.scene, sc.rig_true.left, sc.T_world_left, 0.1, rng, CameraEffects(noise_sigma=sigma),
                           r.rays_left, water_stride=4, water_rays=wl)

    a = view(np.random.default_rng(5), 3.0)
    assert np.array_equal(a, view(np.random.default_rng(5), 3.0))
    # the coarse rays computed inside render_view when not given are the cached ones
    assert np.array_equal(a, render_view(sc.scene, sc.rig_true.left, sc.T_world_left, 0.1,
                                         np.random.default_rng(5), CameraEffects(noise_sigma=3.0), r.rays_left,
                                         water_stride=4))
    clean = view(np.random.default_rng(5), 0.0).astype(float)
    rng = np.random.default_rng(6)
    n1, n2 = view(rng, 3.0) - clean, view(rng, 3.0) - clean  # two frames from one generator
    inner = (clean.min(axis=-1) > 12) & (clean.max(axis=-1) < 243)  # no clipping at 0 or 255
    for n in (n1, n2):
        assert n[inner].std() == pytest.approx(3.0, rel=0.1)
        assert abs(n[inner].mean()) < 0.1
    # consecutive frames get independent noise (another offset into the tile), not a fixed pattern
    assert abs(np.corrcoef(n1[inner].ravel(), n2[inner].ravel())[0, 1]) < 0.05


@pytest.mark.parametrize("bend_mm", [0.0, 12.0])
def test_fast_floater_layer_equals_the_exact_one(bend_mm):
    """The compiled map and footprint, the memoised photo prefilter: the same layer up to float
    rounding, flat or bent; laid over an image in one compiled pass as numpy lays it."""
    sc = random_scene(15, CFG.synthetic, PM, kind="crab", effects=())
    f, T = dataclasses.replace(sc.scene.target, bend_mm=bend_mm), sc.T_world_left
    d = _world_rays(StereoRenderer(sc.rig_true).rays_left, T[:3, :3])
    ref = _floater_layer(f, T[:3, 3], d)
    assert ref[1].max() > 0.99 and ref[2].mean() > 0.99  # the creature is in view, every ray hits its plane
    for _ in range(2):  # the first call fills the cache, the second reads it
        col, cov, valid = _floater_layer(f, T[:3, 3], d, fast=True)
        assert np.allclose(col, ref[0], atol=1e-3) and np.allclose(cov, ref[1], atol=1e-6)
        assert np.array_equal(valid, ref[2])
    rng = np.random.default_rng(2)
    img = rng.uniform(0, 255, (*d.shape[:2], 3)).astype(np.float32)
    shade = rng.uniform(0.6, 1.4, d.shape[:2]).astype(np.float32)
    win = (slice(100, 300), slice(150, 420))
    layer = tuple(a[win] for a in ref)
    laid = [img.copy(), img.copy()]
    for out, fast in zip(laid, (False, True)):
        _lay_floater(out, win, layer, shade, fast)
    assert np.abs(laid[0] - laid[1]).max() < 1e-3 and not np.array_equal(laid[0], img)


def test_coarse_rays_are_block_centre_rays_and_bad_strides_are_refused():
    sc = random_scene(14, CFG.synthetic, PM, kind="squid", effects=())
    rays = StereoRenderer(sc.rig_true).rays_left
    c = coarse_rays(rays, 4)
    assert c.shape == (120, 160, 3)
    assert np.allclose(c[7, 9], rays[28:32, 36:40].reshape(-1, 3).mean(axis=0))
    for bad in (0, 2.5):
        with pytest.raises(InputError, match="water_stride"):
            render_view(Scene(water=sc.scene.water), sc.rig_true.left, sc.T_world_left, water_stride=bad)
