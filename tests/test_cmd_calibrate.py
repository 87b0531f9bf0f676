"""`photoservo calibrate` end to end on rendered board images written to real folders, real
pose CSVs and real MJPG videos; error paths exit 2 with one line."""

import subprocess
import sys
import tomllib

import cv2
import numpy as np
import pytest
from calib_scene import (
    SIZE,
    look_at_flange_poses,
    render_markers,
    render_stereo,
    renderer,
    stereo_board_poses,
    true_hand_eye,
    true_rig,
)

from photoservo.cli.main import main
from photoservo.cli.calibrate.poses import pose_row, read_flange_poses
from photoservo.cli.calibrate.water import set_toml_key
from photoservo.vision.board import Board
from photoservo.vision.calibrate import make_T, rotation_angle_deg
from photoservo.vision.rig import Rig, load_rig, save_rig

CHESS = Board(9, 6, 25.0)
CHARUCO = Board(9, 6, 25.0, charuco=True)
BOARD_ARGS = ["--board", "9x6", "--square-mm", "25"]


def run_cli(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(code, err, text):
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and text in lines[0], err
    assert "Traceback" not in err


@pytest.fixture(scope="module")
def stereo_dirs(tmp_path_factory):
    """8 good chessboard pairs, one pair whose right image has no board, one unpaired image."""
    root = tmp_path_factory.mktemp("stereo")
    rig = true_rig()
    images = render_stereo(CHESS, rig, stereo_board_poses(8, seed=4), noise_sigma=1.5, seed=2)
    for d in ("L", "R"):
        (root / d).mkdir()
    for k, (l, r) in enumerate(images):
        cv2.imwrite(str(root / "L" / f"{k:02d}.png"), l)
        cv2.imwrite(str(root / "R" / f"{k:02d}.png"), r)
    blank = np.full((SIZE[1], SIZE[0], 3), 110, np.uint8)
    cv2.imwrite(str(root / "L" / "08.png"), images[0][0])
    cv2.imwrite(str(root / "R" / "08.png"), blank)
    cv2.imwrite(str(root / "L" / "09_left_only.png"), images[1][0])
    return root


def test_stereo_writes_rig_and_names_skipped_pairs(stereo_dirs, tmp_path, capsys):
    out = tmp_path / "rig.toml"
    code, text, err = run_cli(["calibrate", "stereo", "--left", str(stereo_dirs / "L"), "--right",
                               str(stereo_dirs / "R"), *BOARD_ARGS, "--out", str(out)], capsys)
    assert code == 0, err
    assert "08.png: skipped, board not found in the right image" in text
    assert "unpaired images (in one folder only), skipped: 09_left_only.png" in text
    assert "reprojection RMS: stereo" in text and "07.png " in text
    rig, truth = load_rig(out), true_rig()
    assert rig.left.K[0, 0] == pytest.approx(truth.left.K[0, 0], rel=0.01)
    assert rig.right.K[1, 1] == pytest.approx(truth.right.K[1, 1], rel=0.01)
    assert rig.baseline_mm == pytest.approx(truth.baseline_mm, rel=0.01)
    assert rotation_angle_deg(rig.R.T @ truth.R) < 0.3
    assert rig.hand_eye is None


def test_stereo_too_few_pairs_is_one_line(stereo_dirs, tmp_path, capsys):
    for d in ("L", "R"):
        (tmp_path / d).mkdir()
        for k in range(3):
            (tmp_path / d / f"{k}.png").write_bytes((stereo_dirs / d / f"0{k}.png").read_bytes())
    out = tmp_path / "rig.toml"
    code, _, err = run_cli(["calibrate", "stereo", "--left", str(tmp_path / "L"), "--right", str(tmp_path / "R"),
                            *BOARD_ARGS, "--out", str(out)], capsys)
    assert_one_line_error(code, err, "only 3 usable stereo pairs, need at least 4")
    assert not out.exists()


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--left", "/nonexistent/L", "--right", "/nonexistent/R", *BOARD_ARGS], "--left /nonexistent/L: folder not found"),
        (["--board", "9by6", "--square-mm", "25"], "--board '9by6': expected COLSxROWS"),
        (["--board", "9x6", "--square-mm", "-2"], "--square-mm: -2 must be > 0"),
        (["--board", "1x6", "--square-mm", "25"], "2..100 inner corners per side"),
    ],
)
def test_stereo_input_errors(stereo_dirs, capsys, extra, message):
    argv = ["calibrate", "stereo"]
    if "--left" not in extra:
        argv += ["--left", str(stereo_dirs / "L"), "--right", str(stereo_dirs / "R")]
    code, _, err = run_cli(argv + extra, capsys)
    assert_one_line_error(code, err, message)


def test_stereo_image_size_mismatch_names_file(tmp_path, capsys):
    for d in ("L", "R"):
        (tmp_path / d).mkdir()
    cv2.imwrite(str(tmp_path / "L" / "a.png"), np.zeros((40, 50, 3), np.uint8))
    cv2.imwrite(str(tmp_path / "R" / "a.png"), np.zeros((40, 50, 3), np.uint8))
    cv2.imwrite(str(tmp_path / "L" / "b.png"), np.zeros((40, 60, 3), np.uint8))
    cv2.imwrite(str(tmp_path / "R" / "b.png"), np.zeros((40, 50, 3), np.uint8))
    code, _, err = run_cli(["calibrate", "stereo", "--left", str(tmp_path / "L"), "--right", str(tmp_path / "R"),
                            *BOARD_ARGS], capsys)
    assert_one_line_error(code, err, "b.png: image is 60x40, expected 50x40")


# ----------------------------------------------------------------------------- hand-eye


def T_base_board() -> np.ndarray:
    return make_T(np.diag([1.0, -1.0, -1.0]), np.array([650.0, -50.0, -250.0]))


def write_hand_eye_views(folder, T_bf, board=CHARUCO):
    """Left images of the board from each flange pose + poses.csv (pose columns)."""
    rig, X = true_rig(), true_hand_eye()
    (folder / "left").mkdir(parents=True)
    rows = ["name,x_mm,y_mm,z_mm,rx_rad,ry_rad,rz_rad"]
    for k, T in enumerate(T_bf):
        T_lb = np.linalg.inv(T @ X) @ T_base_board()
        img = renderer(board, rig.left).render(T_lb[:3, :3], T_lb[:3, 3], noise_sigma=1.0,
                                               rng=np.random.default_rng(k))
        cv2.imwrite(str(folder / "left" / f"{k:04d}.png"), img)
        rows.append(",".join([f"{k:04d}.png", *pose_row(T)]))
    (folder / "poses.csv").write_text("\n".join(rows) + "\n")


def rig_file(tmp_path, hand_eye=None):
    r = true_rig()
    path = tmp_path / "rig.toml"
    save_rig(Rig(r.left, r.right, r.R, r.T, hand_eye=hand_eye), path)
    return path


def test_hand_eye_writes_transform_into_rig(tmp_path, capsys):
    views = tmp_path / "views"
    write_hand_eye_views(views, look_at_flange_poses(T_base_board(), true_hand_eye(), 7, seed=11))
    rig = rig_file(tmp_path)
    code, text, err = run_cli(["calibrate", "hand-eye", "--rig", str(rig), "--views", str(views), *BOARD_ARGS,
                               "--charuco"], capsys)
    assert code == 0, err
    assert "warning" not in err
    assert "residual: board position spread" in text
    he = load_rig(rig).hand_eye
    X = true_hand_eye()
    assert he is not None
    assert np.linalg.norm(he[1] - X[:3, 3]) < 3.0
    assert rotation_angle_deg(he[0].T @ X[:3, :3]) < 0.3


def test_hand_eye_pure_translation_warns(tmp_path, capsys):
    views = tmp_path / "views"
    write_hand_eye_views(views, look_at_flange_poses(T_base_board(), true_hand_eye(), 5, seed=12, rotate=False))
    rig = rig_file(tmp_path)
    code, _, err = run_cli(["calibrate", "hand-eye", "--rig", str(rig), "--views", str(views), *BOARD_ARGS,
                            "--charuco", "--out", str(tmp_path / "he.toml")], capsys)
    assert_one_line_error(code, err, "the flange poses vary too little in rotation (largest 0.0 deg")
    assert not (tmp_path / "he.toml").exists()


def test_hand_eye_small_rotation_needs_force(tmp_path, capsys):
    """Poses that rotate only ~5 degrees: refused by default, written with --force and a warning."""
    rng = np.random.default_rng(4)
    X = true_hand_eye()
    T_base_left0 = np.linalg.inv(make_T(np.eye(3), np.array([0.0, 0.0, 0.0]))) @ T_base_board() @ np.linalg.inv(
        make_T(np.eye(3), np.array([-125.0, -87.5, 520.0])))
    T_bf = []
    for k in range(5):
        d = make_T(cv2.Rodrigues(np.radians(rng.uniform(-2.5, 2.5, 3)))[0], rng.uniform(-15, 15, 3))
        T_bf.append(T_base_left0 @ d @ np.linalg.inv(X))
    views = tmp_path / "views"
    write_hand_eye_views(views, T_bf)
    rig = rig_file(tmp_path)
    argv = ["calibrate", "hand-eye", "--rig", str(rig), "--views", str(views), *BOARD_ARGS, "--charuco"]
    code, _, err = run_cli(argv, capsys)
    assert_one_line_error(code, err, "--force writes it anyway")
    assert load_rig(rig).hand_eye is None
    code, _, err = run_cli([*argv, "--force"], capsys)
    assert code == 0 and "warning: the flange poses vary too little in rotation" in err
    assert load_rig(rig).hand_eye is not None


def test_hand_eye_symmetric_chessboard_refused(tmp_path, capsys):
    views = tmp_path / "views"
    views.mkdir()
    code, _, err = run_cli(["calibrate", "hand-eye", "--rig", str(rig_file(tmp_path)), "--views", str(views),
                            "--board", "8x6", "--square-mm", "25"], capsys)
    assert_one_line_error(code, err, "looks the same turned by 180 degrees")


def test_poses_csv_errors_name_line_and_column(tmp_path, capsys):
    views = tmp_path / "views"
    (views / "left").mkdir(parents=True)
    cv2.imwrite(str(views / "left" / "0000.png"), np.zeros((SIZE[1], SIZE[0], 3), np.uint8))
    (views / "poses.csv").write_text("name,x_mm,y_mm,z_mm,rx_rad,ry_rad,rz_rad\n0000,1,2,three,0,0,0\n")
    code, _, err = run_cli(["calibrate", "hand-eye", "--rig", str(rig_file(tmp_path)), "--views", str(views),
                            *BOARD_ARGS, "--charuco"], capsys)
    assert_one_line_error(code, err, "poses.csv line 2: column 'z_mm' is not a number: 'three'")
    (views / "poses.csv").write_text("name,x,y\n0000,1,2\n")
    code, _, err = run_cli(["calibrate", "hand-eye", "--rig", str(rig_file(tmp_path)), "--views", str(views),
                            *BOARD_ARGS, "--charuco"], capsys)
    assert_one_line_error(code, err, "needs columns x_mm,y_mm,z_mm,rx_rad,ry_rad,rz_rad or q1_rad")


def test_poses_csv_joint_columns_use_forward_kinematics(tmp_path):
    from photoservo.robot.pa10 import fk

    q = np.radians([10.0, 30.0, -5.0, 60.0, 15.0, 40.0, -20.0])
    header = "name," + ",".join(f"q{i}_rad" for i in range(1, 8))
    (tmp_path / "p.csv").write_text(header + "\nview1.png," + ",".join(f"{x:.9f}" for x in q) + "\n")
    poses = read_flange_poses(tmp_path / "p.csv")
    assert list(poses) == ["view1"]
    assert np.allclose(poses["view1"], fk(q), atol=1e-6)


def test_pose_row_round_trip(tmp_path):
    T = make_T(cv2.Rodrigues(np.array([0.3, -2.0, 0.7]))[0], np.array([100.0, -20.0, 700.0]))
    (tmp_path / "p.csv").write_text("name,x_mm,y_mm,z_mm,rx_rad,ry_rad,rz_rad\na," + ",".join(pose_row(T)) + "\n")
    assert np.allclose(read_flange_poses(tmp_path / "p.csv")["a"], T, atol=1e-5)


# ----------------------------------------------------------------------------- water


def test_water_prints_height_and_updates_config(tmp_path, capsys):
    """A ChArUco board floating at z = -420 mm, seen by both cameras from one flange pose."""
    water_z = -420.0
    rig_t, X = true_rig(), true_hand_eye()
    T_base_left = make_T(np.diag([1.0, -1.0, -1.0]), np.array([600.0, 0.0, water_z + 560.0]))
    T_bf = T_base_left @ np.linalg.inv(X)
    R_board = np.diag([1.0, -1.0, -1.0])
    T_base_b = make_T(R_board, np.array([650.0, 40.0, water_z]) - R_board @ np.array([125.0, 87.5, 0.0]))
    T_lb = np.linalg.inv(T_base_left) @ T_base_b
    T_rb = make_T(rig_t.R, rig_t.T) @ T_lb
    views = tmp_path / "water"
    for side, cam, T in (("left", rig_t.left, T_lb), ("right", rig_t.right, T_rb)):
        (views / side).mkdir(parents=True)
        cv2.imwrite(str(views / side / "0000.png"), renderer(CHARUCO, cam).render(T[:3, :3], T[:3, 3], noise_sigma=1.0))
    (views / "poses.csv").write_text("name,x_mm,y_mm,z_mm,rx_rad,ry_rad,rz_rad\n0000," + ",".join(pose_row(T_bf)) + "\n")
    cfg = tmp_path / "site.toml"
    cfg.write_text("# my site\n[tracker]\nwater_z_mm = -300.0   # measured by hand\nother = 1\n")
    rig = rig_file(tmp_path, hand_eye=(X[:3, :3], X[:3, 3]))
    code, text, err = run_cli(["calibrate", "water", "--rig", str(rig), "--views", str(views), *BOARD_ARGS,
                               "--charuco", "--update", str(cfg)], capsys)
    assert code == 0, err
    assert "(triangulated)" in text
    from photoservo.tomlconf import configs_dir, read_toml

    known = "water_z_mm" in read_toml(configs_dir() / "default.toml").get("tracker", {})
    assert ("note: 'tracker.water_z_mm' is not a key of configs/default.toml" in text) != known
    z = float(text.split("water_z_mm = ")[1].split()[0])
    assert z == pytest.approx(water_z, abs=2.0)
    doc = tomllib.loads(cfg.read_text())
    assert doc["tracker"]["water_z_mm"] == pytest.approx(z, abs=0.06) and doc["tracker"]["other"] == 1
    assert "# measured by hand" in cfg.read_text() and cfg.read_text().startswith("# my site")


def test_water_needs_hand_eye(tmp_path, capsys):
    (tmp_path / "v").mkdir()
    code, _, err = run_cli(["calibrate", "water", "--rig", str(rig_file(tmp_path)), "--views", str(tmp_path / "v"),
                            *BOARD_ARGS], capsys)
    assert_one_line_error(code, err, "no [hand_eye] table; run `photoservo calibrate hand-eye` first")


def test_set_toml_key_adds_missing_table_and_key():
    assert tomllib.loads(set_toml_key("", "world.water_z_mm", -12.345)) == {"world": {"water_z_mm": -12.35}}
    text = set_toml_key("[world]\nseed = 1\n[sim]\nwater_z_mm = 3.0\n", "world.water_z_mm", 5.0)
    doc = tomllib.loads(text)
    assert doc["world"] == {"seed": 1, "water_z_mm": 5.0} and doc["sim"]["water_z_mm"] == 3.0


# ----------------------------------------------------------------------------- capture and board


def write_video(path, images, fps=20.0):
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (images[0].shape[1], images[0].shape[0]))
    for img in images:
        vw.write(img)
    vw.release()


@pytest.fixture(scope="module")
def board_videos(tmp_path_factory):
    root = tmp_path_factory.mktemp("videos")
    images = render_stereo(CHESS, true_rig(), stereo_board_poses(6, seed=8))
    write_video(root / "l.avi", [l for l, _ in images])
    write_video(root / "r.avi", [r for _, r in images])
    return root


def test_capture_at_interval_saves_pairs_and_preview(board_videos, tmp_path, capsys):
    out, rrd = tmp_path / "cap", tmp_path / "preview.rrd"
    code, text, err = run_cli(["calibrate", "capture", "--videos", str(board_videos / "l.avi"),
                               str(board_videos / "r.avi"), "--interval", "0.09", "--count", "3",
                               "--board", "9x6", "--save", str(rrd), "--out", str(out)], capsys)
    assert code == 0, err
    assert sorted(p.name for p in (out / "left").iterdir()) == ["0000.png", "0001.png", "0002.png"]
    assert sorted(p.name for p in (out / "right").iterdir()) == ["0000.png", "0001.png", "0002.png"]
    assert "board found left, found right" in text
    lines = (out / "capture.csv").read_text().splitlines()
    assert lines[0] == "name,t_left,t_right" and len(lines) == 4
    assert not (out / "poses.csv").exists()
    # the preview recording holds every pair read, with the found corners drawn in colour on
    # the (grey) board images
    from photoservo.record.reader import iter_frames

    frames = list(iter_frames(rrd))
    assert len(frames) >= 3
    for f in frames:
        spread = f.left.astype(int).max(axis=2) - f.left.astype(int).min(axis=2)
        assert spread.max() > 100, "corners drawn in colour"
    saved = cv2.imread(str(out / "left" / "0000.png")).astype(int)
    assert (saved.max(axis=2) - saved.min(axis=2)).max() < 40, "saved pairs are the raw images"


def test_capture_on_enter_in_a_terminal_process(board_videos, tmp_path):
    out = tmp_path / "cap"
    proc = subprocess.run(
        [sys.executable, "-m", "photoservo.cli", "calibrate", "capture", "--videos",
         str(board_videos / "l.avi"), str(board_videos / "r.avi"), "--save", str(tmp_path / "p.rrd"),
         "--out", str(out)],
        input="\n\nq\n", capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 0, proc.stderr
    saved = sorted(p.name for p in (out / "left").iterdir()) if (out / "left").exists() else []
    assert saved == ["0000.png", "0001.png"] and "press Enter" in proc.stdout


def test_capture_missing_video_is_one_line(tmp_path, capsys):
    code, _, err = run_cli(["calibrate", "capture", "--videos", str(tmp_path / "a.avi"), str(tmp_path / "b.avi"),
                            "--out", str(tmp_path / "c")], capsys)
    assert_one_line_error(code, err, "left: video file not found")


def test_board_image_is_detectable(tmp_path, capsys):
    out = tmp_path / "board.png"
    code, text, _ = run_cli(["calibrate", "board", "--board", "9x6", "--square-mm", "25", "--charuco",
                             "--dpi", "100", "--out", str(out)], capsys)
    assert code == 0 and "300 x 225 mm" in text
    from photoservo.vision.board import detect_board

    det = detect_board(cv2.imread(str(out)), CHARUCO)
    assert det is not None and len(det) == CHARUCO.n_corners


# ----------------------------------------------------------------------------- configured cameras and the arm


def test_capture_from_configured_cameras(board_videos, tmp_path, capsys):
    out = tmp_path / "cap"
    code, _text, err = run_cli(["calibrate", "capture", "--set", "cameras.kind=videos",
                               "--set", f"cameras.left={board_videos / 'l.avi'}",
                               "--set", f"cameras.right={board_videos / 'r.avi'}",
                               "--interval", "0.05", "--count", "2", "--save", str(tmp_path / "p.rrd"),
                               "--out", str(out)], capsys)
    assert code == 0, err
    assert sorted(p.name for p in (out / "left").iterdir()) == ["0000.png", "0001.png"]


def test_capture_without_cameras_is_one_line(tmp_path, capsys):
    code, _, err = run_cli(["calibrate", "capture", "--out", str(tmp_path / "c")], capsys)
    assert_one_line_error(code, err, "no cameras: give --devices, --side-by-side, --videos or --folders")
    code, _, err = run_cli(["calibrate", "capture", "--set", "cameras.kind=videos", "--out", str(tmp_path / "c")],
                           capsys)
    assert_one_line_error(code, err, "config key 'cameras.left': must name a device")


def _emulator(q0):
    from photoservo.sim.emulator import Emulator, EmulatorParams
    from photoservo.tomlconf import build_dataclass, configs_dir, read_toml

    params = build_dataclass(EmulatorParams, read_toml(configs_dir() / "default.toml")["emulator"], "emulator")
    return Emulator(params, q0=q0)


Q_LOOK_DOWN = np.radians([0.0, 40.0, 0.0, 80.0, 0.0, 60.0, 0.0])  # flange roughly facing down


def test_capture_logs_flange_pose_from_the_arm(board_videos, tmp_path, capsys):
    """The controller emulator on a real pty, read through the real link: each saved pair gets
    the flange pose (forward kinematics of the joint state at its capture time)."""
    from photoservo.robot.pa10 import fk

    out = tmp_path / "cap"
    with _emulator(Q_LOOK_DOWN) as emu:
        code, _text, err = run_cli(["calibrate", "capture", "--videos", str(board_videos / "l.avi"),
                                   str(board_videos / "r.avi"), "--port", emu.path, "--interval", "0.05",
                                   "--count", "2", "--save", str(tmp_path / "p.rrd"), "--out", str(out)], capsys)
    assert code == 0, err
    poses = read_flange_poses(out / "poses.csv")
    assert list(poses) == ["0000", "0001"]
    for T in poses.values():
        assert np.allclose(T, fk(Q_LOOK_DOWN), atol=1e-3)


def test_water_live_from_cameras_and_arm(tmp_path, capsys):
    """`calibrate water --live`: a board floating at z = -380 mm under the arm's cameras (videos
    rendered from the flange pose of the emulated arm), the pose read through the link."""
    from photoservo.robot.pa10 import fk

    water_z = -380.0
    rig_t, X = true_rig(), true_hand_eye()
    T_base_left = fk(Q_LOOK_DOWN) @ X
    # the board lies on the water, below the left camera, centred on its optical axis
    axis = T_base_left[:3, 2]
    hit = T_base_left[:3, 3] + axis * (water_z - T_base_left[2, 3]) / axis[2]
    R_board = make_T(cv2.Rodrigues(np.array([0.0, 0.0, 0.3]))[0], np.zeros(3))[:3, :3] @ np.diag([1.0, -1.0, -1.0])
    T_bb = make_T(R_board, hit - R_board @ np.array([125.0, 87.5, 0.0]))
    T_lb = np.linalg.inv(T_base_left) @ T_bb
    T_rb = make_T(rig_t.R, rig_t.T) @ T_lb
    assert 300 < T_lb[2, 3] < 900, "the scene must put the board in front of the camera"
    for side, cam, T in (("l", rig_t.left, T_lb), ("r", rig_t.right, T_rb)):
        img = renderer(CHARUCO, cam).render(T[:3, :3], T[:3, 3], noise_sigma=1.0)
        write_video(tmp_path / f"{side}.avi", [img] * 4)
    rig = rig_file(tmp_path, hand_eye=(X[:3, :3], X[:3, 3]))
    with _emulator(Q_LOOK_DOWN) as emu:
        code, text, err = run_cli(["calibrate", "water", "--rig", str(rig), "--live", "--port", emu.path,
                                   "--videos", str(tmp_path / "l.avi"), str(tmp_path / "r.avi"), "--frames", "2",
                                   *BOARD_ARGS, "--charuco"], capsys)
    assert code == 0, err
    assert "(triangulated)" in text
    z = float(text.split("water_z_mm = ")[1].split()[0])
    assert z == pytest.approx(water_z, abs=3.0)


def test_water_needs_views_or_live(tmp_path, capsys):
    X = true_hand_eye()
    code, _, err = run_cli(["calibrate", "water", "--rig", str(rig_file(tmp_path, hand_eye=(X[:3, :3], X[:3, 3]))),
                            *BOARD_ARGS], capsys)
    assert_one_line_error(code, err, "give either --views DIR (saved views) or --live")


def test_capture_into_the_same_folder_continues_the_session(board_videos, tmp_path, capsys):
    out = tmp_path / "cap"
    argv = ["calibrate", "capture", "--videos", str(board_videos / "l.avi"), str(board_videos / "r.avi"),
            "--interval", "0.05", "--count", "2", "--save", str(tmp_path / "p.rrd"), "--out", str(out)]
    assert run_cli(argv, capsys)[0] == 0
    argv[argv.index("--save") + 1] = str(tmp_path / "p2.rrd")   # a recording is never overwritten
    assert run_cli(argv, capsys)[0] == 0
    assert sorted(p.name for p in (out / "left").iterdir()) == [f"{k:04d}.png" for k in range(4)]
    names = [ln.split(",")[0] for ln in (out / "capture.csv").read_text().splitlines()[1:]]
    assert names == ["0000", "0001", "0002", "0003"]


def test_capture_unopenable_port_is_one_line(board_videos, tmp_path, capsys):
    code, _, err = run_cli(["calibrate", "capture", "--videos", str(board_videos / "l.avi"), str(board_videos / "r.avi"),
                            "--port", str(tmp_path / "no-such-tty"), "--interval", "1", "--save", str(tmp_path / "p.rrd"),
                            "--out", str(tmp_path / "c")], capsys)
    assert_one_line_error(code, err, f"--port {tmp_path / 'no-such-tty'}: cannot open")


def test_water_from_single_markers_in_saved_views(tmp_path, capsys):
    """Three 60 mm markers floating at z = -280 mm, one flange pose, `--markers 60`."""
    water_z = -280.0
    rig_t, X = true_rig(), true_hand_eye()
    T_base_left = make_T(np.diag([1.0, -1.0, -1.0]), np.array([600.0, 0.0, water_z + 500.0]))
    face_up = np.diag([1.0, -1.0, -1.0])
    markers = [(k, 60.0, make_T(face_up, np.array([600.0 + x, y, water_z])))
               for k, (x, y) in enumerate([(-40.0, -70.0), (90.0, -50.0), (20.0, 80.0)])]
    left, right = render_markers(rig_t, T_base_left, markers)
    views = tmp_path / "water"
    for side, img in (("left", left), ("right", right)):
        (views / side).mkdir(parents=True)
        cv2.imwrite(str(views / side / "0000.png"), img)
    T_bf = T_base_left @ np.linalg.inv(X)
    (views / "poses.csv").write_text("name,x_mm,y_mm,z_mm,rx_rad,ry_rad,rz_rad\n0000," + ",".join(pose_row(T_bf)) + "\n")
    rig = rig_file(tmp_path, hand_eye=(X[:3, :3], X[:3, 3]))
    code, text, err = run_cli(["calibrate", "water", "--rig", str(rig), "--views", str(views), "--markers", "60"], capsys)
    assert code == 0, err
    assert "3 markers triangulated, 0 by PnP" in text
    z = float(text.split("water_z_mm = ")[1].split()[0])
    assert z == pytest.approx(water_z, abs=2.0)


def test_water_needs_a_target(tmp_path, capsys):
    X = true_hand_eye()
    (tmp_path / "v").mkdir()
    code, _, err = run_cli(["calibrate", "water", "--rig", str(rig_file(tmp_path, hand_eye=(X[:3, :3], X[:3, 3]))),
                            "--views", str(tmp_path / "v")], capsys)
    assert_one_line_error(code, err, "give the floating target: --board COLSxROWS --square-mm S, or --markers SIDE_MM")
