"""`photoservo estimate`: the DESIGN.md JSON on stdout, exit codes 0/1/2, one-line errors, preview."""

from __future__ import annotations

import json

import cv2
import pytest

from photoservo.fileio import write_image_atomic
from photoservo.cli.main import main
from photoservo.config import load_config
from photoservo.vision.rig import save_rig
from photoservo.sim.scenes import random_scene

DESIGN_KEYS = {"found", "position_mm", "rotation", "alpha_px_per_mm", "size_mm", "fitness", "generations", "seconds"}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    cfg = load_config()
    d = tmp_path_factory.mktemp("scene")
    sc = random_scene(21, cfg.synthetic, cfg.photo_model, kind="fish", effects=("noise",), distance_mm=600.0,
                      tilt_deg=10.0)
    write_image_atomic(d / "left.png", sc.left)
    write_image_atomic(d / "right.png", sc.right)
    write_image_atomic(d / "photo.png", sc.photo)
    save_rig(sc.rig, d / "rig.toml")
    empty = random_scene(22, cfg.synthetic, cfg.photo_model, kind="fish", effects=("noise",), empty=True)
    write_image_atomic(d / "empty_left.png", empty.left)
    write_image_atomic(d / "empty_right.png", empty.right)
    return d, sc.truth


def args(d, **over):
    a = {"--rig": d / "rig.toml", "--photo": d / "photo.png", "--left": d / "left.png", "--right": d / "right.png"}
    a.update(over)
    out = ["estimate"]
    for k, v in a.items():
        out += [k, str(v)]
    return out


def test_json_is_the_design_object_and_exit_0(files, capsys):
    d, truth = files
    rc = main(args(d) + ["--json", "--seed", "3", "--preview", str(d / "preview.png")])
    out = capsys.readouterr().out
    assert rc == 0
    js = json.loads(out)  # stdout holds the JSON object and nothing else
    assert set(js) >= DESIGN_KEYS and js["found"] is True
    assert len(js["rotation"]) == 3 and all(len(r) == 3 for r in js["rotation"])
    assert abs(js["position_mm"][2] - truth["position_mm"][2]) < 0.03 * truth["position_mm"][2]
    preview = cv2.imread(str(d / "preview.png"))
    assert preview.shape == (480, 1280, 3)  # both images side by side
    # same seed, same answer
    main(args(d) + ["--json", "--seed", "3"])
    again = json.loads(capsys.readouterr().out)
    js.pop("seconds"), again.pop("seconds")
    assert again == js


def test_empty_water_exit_1_with_null_pose(files, capsys):
    d, _ = files
    rc = main(args(d, **{"--left": d / "empty_left.png", "--right": d / "empty_right.png"}) + ["--json", "--all"])
    js = json.loads(capsys.readouterr().out)
    assert rc == 1 and js["found"] is False
    assert js["position_mm"] is None and js["rotation"] is None and js["size_mm"] is None
    assert isinstance(js["candidates"], list)


def check_error(capsys, argv, needle):
    rc = main(argv)
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert rc == 2 and cap.out == ""
    assert len(lines) == 1 and needle in lines[0], cap.err


def test_missing_file(files, capsys):
    d, _ = files
    check_error(capsys, args(d, **{"--left": d / "nope.png"}), "nope.png")


def test_bad_rig_key(files, capsys):
    d, _ = files
    bad = d / "bad_rig.toml"
    bad.write_text((d / "rig.toml").read_text().replace("dist =", "distortion =", 1))
    check_error(capsys, args(d, **{"--rig": bad}), "distortion")


@pytest.mark.parametrize("roi", ["10,20,30", "a,b,c,d", "0,0,-5,10"])
def test_bad_roi(files, capsys, roi):
    d, _ = files
    check_error(capsys, args(d, **{"--roi": roi}), "--roi")


def test_non_image_photo(files, capsys):
    d, _ = files
    junk = d / "photo.jpg"
    junk.write_text("this is not an image\n")
    check_error(capsys, args(d, **{"--photo": junk}), "photo.jpg")


def test_image_size_must_match_the_rig(files, capsys):
    d, _ = files
    small = d / "small.png"
    write_image_atomic(small, cv2.resize(cv2.imread(str(d / "left.png")), (320, 240)))
    check_error(capsys, args(d, **{"--left": small}), "320x240")


def test_bad_config_key(files, capsys):
    d, _ = files
    check_error(capsys, args(d) + ["--set", "estimator.nonsense=1"], "estimator.nonsense")
