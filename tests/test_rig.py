import cv2
import numpy as np
import pytest

from photoservo.errors import InputError
from photoservo.vision.rig import Camera, default_rig, dump_rig, load_rig, parse_rig, project_points


def test_project_points_matches_opencv_with_distortion():
    rng = np.random.default_rng(0)
    K = np.array([[812.0, 0.3, 321.0], [0.0, 805.0, 238.0], [0.0, 0.0, 1.0]])
    dist = np.array([-0.21, 0.08, 0.001, -0.0015, -0.01])
    cam = Camera(size=(640, 480), K=K, dist=dist)
    X = np.column_stack([rng.uniform(-300, 300, 200), rng.uniform(-200, 200, 200), rng.uniform(300, 3000, 200)])
    ours = project_points(X, cam)
    ref, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, dist)
    assert np.allclose(ours, ref.reshape(-1, 2), atol=1e-6)


def test_points_behind_camera_are_nan():
    uv = project_points(np.array([[0.0, 0.0, -5.0], [1.0, 2.0, 100.0]]), default_rig().left)
    assert np.all(np.isnan(uv[0])) and np.all(np.isfinite(uv[1]))


def test_rig_toml_round_trip(tmp_path):
    rig = default_rig()
    rig = type(rig)(left=rig.left, right=rig.right, R=rig.R, T=rig.T,
                    hand_eye=(np.eye(3), np.array([10.0, 0.0, 50.0])))
    p = tmp_path / "rig.toml"
    p.write_text(dump_rig(rig))
    back = load_rig(p)
    assert np.allclose(back.left.K, rig.left.K) and np.allclose(back.T, rig.T)
    assert back.hand_eye is not None and np.allclose(back.hand_eye[1], [10, 0, 50])
    assert back.baseline_mm == pytest.approx(100.0)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d.pop("stereo"), "missing table [stereo]"),
        (lambda d: d["left"].update(K=[[1, 0], [0, 1]]), "key 'K' must have shape"),
        (lambda d: d["stereo"].update(R=[[1, 0, 0], [0, 1, 0], [0, 0, 2]]), "'R' is not a rotation"),
        (lambda d: d["right"].update(size=[640]), "key 'size'"),
        (lambda d: d["left"].update(focal=3), "unknown key 'focal'"),
        (lambda d: d["stereo"].update(T=[0, 0, 0]), "baseline"),
    ],
)
def test_rig_errors_name_the_key(mutate, message):
    import tomllib

    doc = tomllib.loads(dump_rig(default_rig()))
    mutate(doc)
    with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]")):
        parse_rig(doc, "rig.toml")


def test_missing_rig_file_is_input_error(tmp_path):
    with pytest.raises(InputError, match="cannot read rig file"):
        load_rig(tmp_path / "nope.toml")
