"""The compact recording's planes (issue 13): hue classes score exactly as the hues they stand
for in every reader of the fitness input, grey planes round-trip through the BGR a replay
rebuilds, and the plane container keeps any field of the fitness input, losslessly."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoservo.record.planes import (
    GREY_RADIUS_PX,
    decode_planes,
    encode_planes,
    grey_near_target,
    hue_class_lut,
    tracker_input,
    tracker_planes,
)
from photoservo.config import load_config
from photoservo.vision.seeding import target_blobs
from photoservo.vision.fitness import StereoHue, counts_compiled, counts_reference
from photoservo.vision.photo_model import HUE_BINS, NO_HUE, PhotoModel
from photoservo.vision.rig import default_rig

W, H = 96, 72


def _model(rng: np.random.Generator, n_hues: int) -> PhotoModel:
    centre = int(rng.integers(0, HUE_BINS))
    inner_hue = ((centre + rng.integers(-n_hues, n_hues + 1, 60)) % HUE_BINS).astype(np.uint8)
    target = np.zeros(HUE_BINS, bool)
    target[(centre + np.arange(-2 * n_hues, 2 * n_hues + 1)) % HUE_BINS] = True
    return PhotoModel(inner_uv=rng.normal(0, 8, (60, 2)), inner_hue=inner_hue,
                      outer_uv=rng.normal(0, 14, (40, 2)), target_hues=target, size_px=(30.0, 20.0),
                      origin_px=(40.0, 30.0), mask=np.zeros((H, W), np.uint8))


def _hue(rng: np.random.Generator) -> np.ndarray:
    h = rng.integers(0, HUE_BINS, (H, W)).astype(np.uint8)
    h[rng.random((H, W)) < 0.1] = NO_HUE
    return h


@settings(max_examples=25, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**31 - 1), n_hues=st.integers(0, 40), tol=st.integers(0, 90))
def test_hue_classes_score_exactly_as_the_hues(seed: int, n_hues: int, tol: int):
    """Fitness counts (reference and compiled kernel), the estimator's target blobs and the
    target mask are the same on the class image as on the hue image."""
    rng = np.random.default_rng(seed)
    model, rig = _model(rng, n_hues), default_rig()
    fit = dataclasses.replace(load_config().fitness, hue_tolerance=tol)
    lut = hue_class_lut(model.inner_hue, model.target_hues, tol)
    assert np.array_equal(lut[lut], lut) and lut[NO_HUE] == NO_HUE        # idempotent, NO_HUE kept
    full = StereoHue(_hue(rng), _hue(rng))
    classes = StereoHue(lut[full.left], lut[full.right])
    P = 40                                                               # poses around the view
    R = np.stack([cv2.Rodrigues(rng.normal(0, 0.3, 3))[0] for _ in range(P)])
    t = np.column_stack([rng.normal(0, 30, P), rng.normal(0, 30, P), rng.uniform(250, 600, P)])
    alpha = rng.uniform(0.5, 3.0, P)
    for counts in (counts_reference, counts_compiled):
        assert np.array_equal(counts(R, t, alpha, model, full, rig, fit), counts(R, t, alpha, model, classes, rig, fit))
    blobs = [target_blobs(h, model.target_hues, 5) for h in (full.left, classes.left)]
    assert len(blobs[0]) == len(blobs[1])
    for a, b in zip(*blobs):
        assert all(np.array_equal(x, y) for x, y in zip(dataclasses.astuple(a), dataclasses.astuple(b)))


def test_water_collapses_to_one_class():
    model = _model(np.random.default_rng(1), 4)
    lut = hue_class_lut(model.inner_hue, model.target_hues, 10)
    far = [h for h in range(HUE_BINS) if not model.target_hues[h]
           and min(min(abs(h - v), HUE_BINS - abs(h - v)) for v in model.inner_hue.astype(int)) > 10]
    assert len(set(lut[far].tolist())) == 1 and len(far) > 100


def test_grey_planes_rebuild_bgr_whose_grey_is_the_plane_near_the_target():
    rng = np.random.default_rng(2)
    model = _model(rng, 3)
    bgr = [rng.integers(0, 256, (H, W, 3), dtype=np.uint8) for _ in range(2)]
    hue = StereoHue(*(np.full((H, W), 100, np.uint8) for _ in range(2)))
    target_hue = int(np.flatnonzero(model.target_hues)[0])
    hue.left[30, 40] = hue.right[10, 10] = target_hue
    planes = decode_planes(encode_planes(tracker_planes(hue, *bgr, None, model.target_hues)))
    fitness_input, left, right = tracker_input(planes, StereoHue)
    assert np.array_equal(fitness_input.left, hue.left) and np.array_equal(fitness_input.right, hue.right)
    for side, img, (y, x) in (("left", left, (30, 40)), ("right", right, (10, 10))):
        r = GREY_RADIUS_PX[side]
        grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        original = cv2.cvtColor(bgr[0 if side == "left" else 1], cv2.COLOR_BGR2GRAY)
        near = np.zeros((H, W), bool)
        near[max(0, y - r):y + r + 1, max(0, x - r):x + r + 1] = True
        assert np.array_equal(grey[near], original[near]) and not grey[~near].any()
    assert np.array_equal(grey_near_target(bgr[0], hue.left, None, 3), cv2.cvtColor(bgr[0], cv2.COLOR_BGR2GRAY))


def test_grey_planes_are_stored_cropped_and_come_back_whole():
    """A grey plane is stored as the rectangle around its non-zero pixels and decoded to its full
    size (0 around), an all-zero one too; a blob of an older recording (whole planes) decodes
    as before."""
    import io

    rng = np.random.default_rng(4)
    grey = np.zeros((H, W), np.uint8)
    grey[20:31, 33:52] = rng.integers(1, 256, (11, 19), dtype=np.uint8)
    planes = {"grey/left": grey, "grey/right": np.zeros((H, W), np.uint8), "fitness/left": _hue(rng)}
    blob = encode_planes(planes)
    with np.load(io.BytesIO(blob)) as npz:
        keys = set(npz.files)
        cropped = cv2.imdecode(npz[f"grey/left@{H}x{W}+20+33.png"], cv2.IMREAD_UNCHANGED)
    assert keys == {f"grey/left@{H}x{W}+20+33.png", f"grey/right@{H}x{W}+0+0.png", "fitness/left.png"}
    assert cropped.shape == (11, 19)
    out = decode_planes(blob)
    assert set(out) == set(planes) and all(np.array_equal(out[k], planes[k]) for k in planes)
    old = io.BytesIO()
    np.savez(old, **{f"{k}.png": cv2.imencode(".png", a)[1].reshape(-1) for k, a in planes.items()})
    out = decode_planes(old.getvalue())
    assert set(out) == set(planes) and all(np.array_equal(out[k], planes[k]) for k in planes)


def test_the_container_keeps_any_field_of_the_fitness_input():
    """A plane added to the fitness input later (another dtype too) is recorded and rebuilt;
    a recording without it says which plane it lacks."""
    @dataclasses.dataclass(frozen=True)
    class Wider:
        left: np.ndarray
        right: np.ndarray
        saturation_left: np.ndarray
        weights: np.ndarray

    rng = np.random.default_rng(3)
    x = Wider(_hue(rng), _hue(rng), rng.integers(0, 256, (H, W), dtype=np.uint8),
              rng.normal(size=(4, 5)).astype(np.float32))
    bgr = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    planes = decode_planes(encode_planes(tracker_planes(x, bgr, bgr, None, None)))
    y, _, _ = tracker_input(planes, Wider)
    for f in dataclasses.fields(Wider):
        a, b = getattr(x, f.name), getattr(y, f.name)
        assert a.dtype == b.dtype and np.array_equal(a, b), f.name
    del planes["fitness/saturation_left"]
    with pytest.raises(KeyError, match="saturation_left"):
        tracker_input(planes, Wider)


def test_a_frame_the_estimator_seeds_from_the_hue_layout_keeps_its_raw_hues():
    """vision/hue_layout.py reads hue values (soft bins), not only the class tests: a frame with
    more than estimator.layout_share of its hued pixels in target hues is kept unreduced."""
    from photoservo.record.planes import frame_lut

    model = _model(np.random.default_rng(4), 3)
    lut = hue_class_lut(model.inner_hue, model.target_hues, 10)
    water = np.full((H, W), int(np.flatnonzero(~model.target_hues)[0]), np.uint8)
    assert frame_lut(lut, water, model.target_hues, 0.3) is lut
    many = water.copy()
    many[: H // 2] = int(np.flatnonzero(model.target_hues)[0])
    assert frame_lut(lut, many, model.target_hues, 0.3) is None
    assert frame_lut(lut, many, model.target_hues, 0.6) is lut
