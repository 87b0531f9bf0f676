"""Synthetic scenes (issue 2 item 7): geometry of the renderer against `project_points` (with
lens distortion), ground truth of `random_scene`, empty water, determinism, and `photoservo synth`."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from photoservo.cli.main import main
from photoservo.config import load_config
from photoservo.vision.photo_model import build_photo_model, hue_image
from photoservo.vision.rig import Camera, Rig, load_rig, project_points
from photoservo.sim.renderer import (
    CameraEffects,
    Scene,
    calm_water,
    floater_from_model,
    lying_on_water,
    make_transform,
    render_stereo,
    render_view,
    stereo_transform,
)
from photoservo.sim.scenes import EFFECTS, random_scene, synthetic_rig

CFG = load_config()


def half_rig() -> Rig:
    """synthetic_rig() at half resolution (same field of view and distortion): faster tests."""
    r = synthetic_rig()

    def half(c: Camera) -> Camera:
        K = c.K.copy()
        K[:2] *= 0.5
        K[0, 2], K[1, 2] = (c.K[0, 2] + 0.5) / 2 - 0.5, (c.K[1, 2] + 0.5) / 2 - 0.5
        return Camera((c.size[0] // 2, c.size[1] // 2), K, c.dist.copy())

    return Rig(half(r.left), half(r.right), r.R, r.T)


MARKS_UV = np.array([[0.0, 0.0], [-45.0, -18.0], [45.0, -18.0], [45.0, 18.0], [-45.0, 18.0]])  # px from origin


def marked_photo() -> np.ndarray:
    """A red ellipse on white with green discs at its bounding-box centre (the model origin)
    and at the offsets MARKS_UV (photo px)."""
    photo = np.full((121, 201, 3), 250, np.uint8)
    cv2.ellipse(photo, (100, 60), (80, 40), 0, 0, 360, (30, 30, 220), -1)
    for du, dv in MARKS_UV:
        cv2.circle(photo, (int(100 + du), int(60 + dv)), 8 if du else 12, (40, 200, 40), -1)
    return photo


def green_blobs(img: np.ndarray) -> np.ndarray:
    """Centroids (N, 2) px of the green marker blobs in an image."""
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
    m = ((np.abs(hsv[..., 0].astype(int) - 60) < 12) & (hsv[..., 1] > 100)).astype(np.uint8)
    _, _, stats, cents = cv2.connectedComponentsWithStats(m)
    return cents[1:][stats[1:, cv2.CC_STAT_AREA] >= 4]


def green_centroid(img: np.ndarray) -> np.ndarray:
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
    m = (np.abs(hsv[..., 0].astype(int) - 60) < 12) & (hsv[..., 1] > 100)
    ys, xs = np.nonzero(m)
    assert xs.size > 10, "the green marker is not in the image"
    return np.array([xs.mean(), ys.mean()])


def test_target_origin_lands_where_project_points_puts_it_with_distortion():
    """Looking straight down from 500 mm with the marked photo placed near the image corner,
    where the barrel distortion moves it ~4 px: the rendered marker sits on project_points."""
    rig = synthetic_rig()
    photo = marked_photo()
    model = build_photo_model(photo, CFG.photo_model)
    assert model.origin_px == (100.0, 60.0)
    R_wl = np.diag([1.0, -1.0, -1.0])  # camera looks down, image x along world x
    T_world_left = make_transform(R_wl, np.array([0.0, 0.0, 500.0]))
    X_left = np.array([150.0, -105.0, 500.0])  # towards the top-right corner of the left image
    P_world = R_wl @ X_left + T_world_left[:3, 3]
    target = floater_from_model(photo, model, 2.0, lying_on_water(P_world, 0.3))
    scene = Scene(water=calm_water(0, wave_slope=0.0, glint=0.0), target=target)
    left, right = render_stereo(scene, rig, T_world_left)
    uv_l = project_points(X_left, rig.left)
    uv_r = project_points(rig.R @ X_left + rig.T, rig.right)
    assert np.linalg.norm(green_centroid(left) - uv_l) < 0.5
    assert np.linalg.norm(green_centroid(right) - uv_r) < 0.5
    # the test can fail: ignoring the distortion would put the origin far off
    ideal = Camera(rig.left.size, rig.left.K, np.zeros(5))
    assert np.linalg.norm(project_points(X_left, ideal) - uv_l) > 3


@pytest.mark.parametrize("seed", [1, 2])
def test_random_scene_truth_projects_onto_the_rendered_origin(seed):
    """Same-photo ground truth: the model origin (truth pose) projected with the rig that
    rendered the images lands on the marker in both images, and the truth's tilt/size agree."""
    photo = marked_photo()
    sc = random_scene(seed, CFG.synthetic, CFG.photo_model, photo=photo, effects=(), rig=half_rig(),
                      distance_mm=350.0 + 100 * seed)
    t = sc.truth
    X = np.array(t["position_mm"])
    R = np.array(t["rotation"])
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-9)
    assert t["distance_mm"] == pytest.approx(X[2])
    assert t["tilt_deg"] == pytest.approx(np.degrees(np.arccos(R[2, 2])))
    assert X[2] == pytest.approx(350.0 + 100 * seed)
    assert t["tilt_deg"] <= CFG.synthetic.tilt_max_deg + 1e-9
    # every marker lands where the truth pose and alpha project it (origin, scale, rotation, tilt)
    a = t["alpha_px_per_mm"]
    X_marks = np.column_stack([MARKS_UV / a, np.zeros(len(MARKS_UV))]) @ R.T + X
    rt = sc.rig_true
    for img, uv in ((sc.left, project_points(X_marks, rt.left)),
                    (sc.right, project_points(X_marks @ rt.R.T + rt.T, rt.right))):
        blobs = green_blobs(img)
        assert len(blobs) == len(MARKS_UV)
        err = np.linalg.norm(blobs[:, None, :] - uv[None, :, :], axis=-1).min(axis=0)
        assert err.max() < 0.6, err
    model = build_photo_model(photo, CFG.photo_model)
    assert t["size_mm"] == pytest.approx([model.size_px[0] / t["alpha_px_per_mm"], model.size_px[1] / t["alpha_px_per_mm"]])
    # the written rig differs from the rendering rig by the configured calibration error
    dR = sc.rig_true.R @ sc.rig.R.T
    angle = np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1)))
    assert angle == pytest.approx(CFG.synthetic.calib_rotation_deg, abs=1e-6)
    assert abs(sc.rig_true.left.K[0, 0] / sc.rig.left.K[0, 0] - 1) == pytest.approx(CFG.synthetic.calib_focal_pct / 100)


def test_other_photo_truth_describes_the_estimators_photo():
    same = random_scene(4, CFG.synthetic, CFG.photo_model, kind="fish", effects=(), rig=half_rig())
    other = random_scene(4, CFG.synthetic, CFG.photo_model, kind="fish", other_photo=True, effects=(), rig=half_rig())
    assert np.array_equal(same.left, other.left)  # the same creature floats in both
    assert other.truth["same_photo"] is False and same.truth["same_photo"] is True
    mb = build_photo_model(other.photo, CFG.photo_model)
    a = other.truth["alpha_px_per_mm"]
    assert other.truth["size_mm"] == pytest.approx([mb.size_px[0] / a, mb.size_px[1] / a])
    # the other individual is drawn smaller: fewer px per mm, a similar real size
    assert a < same.truth["alpha_px_per_mm"]
    assert other.truth["size_mm"][0] == pytest.approx(same.truth["size_mm"][0], rel=0.15)
    d = np.linalg.norm(np.subtract(other.truth["position_mm"], same.truth["position_mm"]))
    assert d < 0.1 * same.truth["size_mm"][0]


def test_empty_water_has_no_target_hue():
    sc = random_scene(5, CFG.synthetic, CFG.photo_model, kind="squid", empty=True, rig=half_rig())
    assert sc.truth["found"] is False and sc.truth["position_mm"] is None and sc.truth["rotation"] is None
    pm = CFG.photo_model
    model = build_photo_model(sc.photo, pm)
    for img in (sc.left, sc.right):
        hue = hue_image(img, pm.min_saturation, pm.min_value)
        has = hue != 255
        assert has.mean() > 0.5  # water carries a hue...
        assert model.target_hues[hue[has]].mean() < 0.001  # ...never the squid's


def test_target_is_there_in_a_full_scene():
    sc = random_scene(6, CFG.synthetic, CFG.photo_model, kind="crab", rig=half_rig())
    model = build_photo_model(sc.photo, CFG.photo_model)
    pm = CFG.photo_model
    for img in (sc.left, sc.right):
        hue = hue_image(img, pm.min_saturation, pm.min_value)
        assert (model.target_hues[np.minimum(hue, 179)] & (hue != 255)).sum() > 200


def test_same_seed_same_scene_and_different_seed_differs():
    a = random_scene(7, CFG.synthetic, CFG.photo_model, effects=EFFECTS, distractor=True, rig=half_rig())
    b = random_scene(7, CFG.synthetic, CFG.photo_model, effects=EFFECTS, distractor=True, rig=half_rig())
    c = random_scene(8, CFG.synthetic, CFG.photo_model, effects=EFFECTS, distractor=True, rig=half_rig())
    assert np.array_equal(a.left, b.left) and np.array_equal(a.right, b.right) and a.truth == b.truth
    assert not np.array_equal(a.left, c.left)
    assert a.truth["distractors"] and set(a.truth["effects"]) == set(EFFECTS)


def test_camera_effects_change_the_image():
    rig = half_rig()
    sc = random_scene(9, CFG.synthetic, CFG.photo_model, effects=(), rig=rig)
    plain = render_stereo(sc.scene, sc.rig_true, sc.T_world_left)[0]
    assert np.array_equal(plain, sc.left)
    jpeg = render_stereo(sc.scene, sc.rig_true, sc.T_world_left,
                         effects=(CameraEffects(jpeg_quality=60), CameraEffects()))[0]
    wb = render_stereo(sc.scene, sc.rig_true, sc.T_world_left,
                       effects=(CameraEffects(white_balance=(1.1, 1.0, 0.9)), CameraEffects()))[0]
    assert 0 < np.abs(jpeg.astype(int) - plain).mean() < 6
    assert wb[..., 0].mean() > plain[..., 0].mean() and wb[..., 2].mean() < plain[..., 2].mean()


def test_right_camera_pose_follows_the_rig():
    rig = synthetic_rig()
    T_rl = stereo_transform(rig)
    X_left = np.array([10.0, -20.0, 700.0])
    assert np.allclose((T_rl @ [*X_left, 1])[:3], rig.R @ X_left + rig.T)


def test_synth_cli_writes_all_files(tmp_path, capsys):
    out = tmp_path / "scene"
    assert main(["synth", "--specimen", "fish", "--seed", "2", "--distance", "800", "--tilt-deg", "20",
                 "--effects", "waves,noise,chroma", "--out", str(out)]) == 0
    for name in ("left.png", "right.png", "rig.toml", "truth.json", "photo.png"):
        assert (out / name).is_file(), name
    rig = load_rig(out / "rig.toml")
    assert np.allclose(rig.left.K, synthetic_rig().left.K)
    truth = json.loads((out / "truth.json").read_text())
    assert truth["found"] is True and truth["distance_mm"] == pytest.approx(800.0)
    assert truth["tilt_deg"] == pytest.approx(20.0)
    assert {"position_mm", "rotation", "alpha_px_per_mm", "size_mm", "fitness", "generations", "seconds"} <= set(truth)
    assert cv2.imread(str(out / "left.png")).shape == (480, 640, 3)
    assert "truth.json" in capsys.readouterr().out


@pytest.mark.parametrize("argv, what", [
    (["--specimen", "squid", "--effects", "waves,sparkles"], "sparkles"),
    (["--specimen", "squid", "--distance", "-5"], "--distance"),
    (["--specimen", "squid", "--tilt-deg", "80"], "--tilt-deg"),
    (["--photo", "MISSING.png"], "MISSING.png"),
    (["--photo", "BLANK"], "no separable target"),
    (["--photo", "BLANK", "--other"], "--other"),
    (["--specimen", "squid", "--set", "synthetic.tilt_max_deg=99"], "tilt_max_deg"),
])
def test_synth_cli_refuses_bad_input(tmp_path, capsys, argv, what):
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((60, 80, 3), 255, np.uint8))
    argv = [str(blank) if a == "BLANK" else str(tmp_path / a) if a == "MISSING.png" else a for a in argv]
    out = tmp_path / "out"
    assert main(["synth", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and what in err[0]
    assert not out.exists()


def test_compiled_water_pass_matches_the_numpy_reference():
    """The numba water pass renders the same model as `_shade_water` (numpy reference)."""
    sc = random_scene(10, CFG.synthetic, CFG.photo_model, effects=EFFECTS, distractor=True, rig=half_rig())
    cam = sc.rig_true.left
    a = render_view(sc.scene, cam, sc.T_world_left, 0.37, compiled=True)
    b = render_view(sc.scene, cam, sc.T_world_left, 0.37, compiled=False)
    diff = np.abs(a.astype(int) - b)
    assert diff.mean() < 0.3 and np.percentile(diff, 99) <= 2
    # time moves the waves
    c = render_view(sc.scene, cam, sc.T_world_left, 1.37, compiled=True)
    assert np.abs(c.astype(int) - a).mean() > 1
