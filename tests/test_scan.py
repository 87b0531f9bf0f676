"""`photoservo scan`: fitness maps around a pose, written as PNGs, peak near the truth."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from _fitness_scene import ALPHA_TRUE, R_TRUE, T_TRUE, make_photo, render_stereo

from photoservo.cli.main import main
from photoservo.config import load_config
from photoservo.vision.photo_model import build_photo_model
from photoservo.vision.rig import default_rig, save_rig
from photoservo.vision.scan import ScanSlice, draw_slice, slice_poses


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    d = tmp_path_factory.mktemp("scan")
    photo, _ = make_photo()
    model = build_photo_model(photo, load_config().photo_model)
    rig = default_rig()
    left, right = render_stereo(photo, model, rig, R_TRUE, T_TRUE, ALPHA_TRUE)
    for name, img in (("photo.png", photo), ("left.png", left), ("right.png", right)):
        cv2.imwrite(str(d / name), img)
    save_rig(rig, d / "rig.toml")
    (d / "truth.json").write_text(json.dumps({
        "found": True, "position_mm": T_TRUE.tolist(), "rotation": R_TRUE.tolist(),
        "alpha_px_per_mm": ALPHA_TRUE, "size_mm": [model.size_px[0], model.size_px[1]],
        "fitness": None, "generations": 0, "seconds": 0.0}))
    return d


def args(d, out, *extra):
    return ["scan", "--rig", str(d / "rig.toml"), "--photo", str(d / "photo.png"),
            "--left", str(d / "left.png"), "--right", str(d / "right.png"),
            "--pose", str(d / "truth.json"), "--out", str(out), *extra]


def test_scan_writes_maps_with_the_peak_at_the_truth(scene, tmp_path, capsys):
    out = tmp_path / "maps"
    assert main(args(scene, out, "--axes", "x,z,rz", "--steps", "21", "--span-mm", "40",
                     "--span-deg", "30", "--alpha-factor", "1.5")) == 0
    cap = capsys.readouterr()
    assert cap.err == ""  # stderr is not a terminal here: no progress bar, no \r updates
    doc = json.loads((out / "scan.json").read_text())
    assert [m["axis"] for m in doc["maps"]] == ["x", "z", "rz"]
    for m in doc["maps"]:
        img = cv2.imread(m["png"])
        assert img is not None and img.shape[0] > 300 and img.shape[1] > 500
        F = np.array(m["fitness"])
        assert F.shape == (21, 21)
        step = 2 * (40 if m["unit"] == "mm" else 30) / 20
        assert abs(m["peak"]["offset"]) <= step + 1e-9, m["axis"]
        assert m["peak"]["alpha_px_per_mm"] == pytest.approx(ALPHA_TRUE, rel=0.05)
        assert m["peak"]["fitness"] > 0.9
        assert f"{m['axis']}: peak fitness" in cap.out


@pytest.mark.parametrize("mutate, needle", [
    (lambda d: (d / "truth.json").write_text('{"found": false, "position_mm": null}'), "found"),
    (lambda d: (d / "truth.json").write_text("{not json"), "not valid JSON"),
    (lambda d: (d / "truth.json").write_text('{"found": true, "position_mm": [1, 2], "rotation": '
                                             '[[1,0,0],[0,1,0],[0,0,1]], "alpha_px_per_mm": 1}'),
     "position_mm"),
    (lambda d: (d / "left.png").write_bytes(b"not an image"), "left.png"),
])
def test_bad_input_exits_2_with_one_line(tmp_path, mutate, needle, capsys):
    photo, _ = make_photo()
    rig = default_rig()
    model = build_photo_model(photo, load_config().photo_model)
    left, right = render_stereo(photo, model, rig, R_TRUE, T_TRUE, ALPHA_TRUE)
    cv2.imwrite(str(tmp_path / "photo.png"), photo)
    cv2.imwrite(str(tmp_path / "left.png"), left)
    cv2.imwrite(str(tmp_path / "right.png"), right)
    save_rig(rig, tmp_path / "rig.toml")
    (tmp_path / "truth.json").write_text(json.dumps({
        "found": True, "position_mm": T_TRUE.tolist(), "rotation": R_TRUE.tolist(), "alpha_px_per_mm": 1.0}))
    mutate(tmp_path)
    out = tmp_path / "maps"
    assert main(args(tmp_path, out, "--steps", "5")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]
    assert not out.exists()  # nothing half-written


def test_bad_axis_and_steps_exit_2(scene, tmp_path, capsys):
    assert main(args(scene, tmp_path / "o", "--axes", "x,w")) == 2
    assert "--axes" in capsys.readouterr().err
    assert main(args(scene, tmp_path / "o", "--steps", "1")) == 2
    assert "--steps" in capsys.readouterr().err


def test_slice_poses_directions():
    """Position axes move along the LEFT camera axes; rz turns about the model normal."""
    R, t = slice_poses("y", R_TRUE, T_TRUE, np.array([-5.0, 10.0]))
    np.testing.assert_allclose(t - T_TRUE, [[0, -5, 0], [0, 10, 0]])
    np.testing.assert_allclose(R, [R_TRUE, R_TRUE])
    R, t = slice_poses("rz", R_TRUE, T_TRUE, np.array([90.0]))
    np.testing.assert_allclose(R[0][:, 2], R_TRUE[:, 2], atol=1e-12)  # the normal stays
    np.testing.assert_allclose(R[0][:, 0], R_TRUE[:, 1], atol=1e-12)  # model x turns onto model y


def test_draw_slice_marks_the_peak():
    F = np.zeros((11, 11))
    F[8, 2] = 1.0
    s = ScanSlice(axis="x", unit="mm", offsets=np.linspace(-10, 10, 11),
                  alphas=np.geomspace(0.5, 2, 11), fitness=F, alpha0=1.0)
    assert s.peak() == pytest.approx((-6.0, float(np.geomspace(0.5, 2, 11)[8]), 1.0))
    img = draw_slice(s, "test", plot_w=220, plot_h=220)
    assert img.dtype == np.uint8 and img.ndim == 3
    # the peak cell is yellow (viridis max) and sits upper-left of centre: high alpha, negative x
    plot = img[56:56 + 220, 90:90 + 220]  # the plot area (margins of draw_slice)
    ys, xs = np.nonzero((plot[..., 2] > 200) & (plot[..., 1] > 200) & (plot[..., 0] < 80))
    assert len(xs) > 50
    assert xs.mean() == pytest.approx(2.5 * 20, abs=3) and ys.mean() == pytest.approx(220 - 8.5 * 20, abs=3)
