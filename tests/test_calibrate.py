"""Calibration maths against boards rendered from a known rig, hand-eye transform and flange
poses (tests/calib_scene.py). Tolerances are stated in each test; the numbers recovered on this
scene are in the commit message / report."""

import math

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

from photoservo.errors import InputError
from photoservo.vision.board import Board, detect_board, match_order, reversed_order
from photoservo.vision.calibrate import (
    board_points_left,
    board_pose,
    calibrate_hand_eye,
    calibrate_stereo,
    fit_water_plane,
    flag_outliers,
    hand_eye_motion_warnings,
    make_T,
    pair_detections,
    rotation_angle_deg,
)
from photoservo.vision.rig import project_points

CHESS = Board(9, 6, 25.0)
CHARUCO = Board(9, 6, 25.0, charuco=True)


@pytest.fixture(scope="module")
def rig():
    return true_rig()


def detect_pairs(board, images):
    return [detect_board(l, board) for l, _ in images], [detect_board(r, board) for _, r in images]


@pytest.mark.parametrize("board", [CHESS, CHARUCO], ids=["chess", "charuco"])
def test_renderer_agrees_with_project_points(rig, board):
    """The rendered corners sit where cv2.projectPoints-consistent maths puts them (< 0.25 px
    mean): the renderer is a fair ground truth."""
    T = stereo_board_poses(1, seed=5)[0]
    img = renderer(board, rig.left).render(T[:3, :3], T[:3, 3])
    det = detect_board(img, board)
    assert det is not None and len(det) >= 30
    truth = project_points(board.object_points()[det.ids] @ T[:3, :3].T + T[:3, 3], rig.left)
    err = np.linalg.norm(det.image_points - truth, axis=1)
    assert err.mean() < 0.25 and err.max() < 1.0


# Tolerances per board kind (10 views, 480x360 px, 2 grey levels of noise): the chessboard's
# corners are all found and refined to ~0.1 px; at this small image size the ChArUco markers are
# ~15 px wide and only 30-45 of the 54 corners are found per view, so it is held to looser ones.
TOLERANCE = {  # focal (relative), principal point (px), baseline (relative), rotation (deg)
    CHESS: (0.004, 3.0, 0.003, 0.3),
    CHARUCO: (0.01, 4.0, 0.006, 0.4),
}
# The stereo rotation error follows the principal-point error (1 px ~ 0.1 deg at f = 520 px),
# which these views (tilts of 15-35 deg) pin down to 1-2 px: median 0.05-0.25 deg over seeds
# in benchmarks/calibration.py.


def check_rig(cal, rig, board):
    """Focal lengths, principal points, baseline and stereo rotation against the truth
    (TOLERANCE); the direction of T within 1 deg."""
    f_tol, c_tol, b_tol, r_tol = TOLERANCE[board]
    for est, true in ((cal.rig.left, rig.left), (cal.rig.right, rig.right)):
        assert est.K[0, 0] == pytest.approx(true.K[0, 0], rel=f_tol)
        assert est.K[1, 1] == pytest.approx(true.K[1, 1], rel=f_tol)
        assert np.hypot(*(est.K[:2, 2] - true.K[:2, 2])) < c_tol
    assert cal.rig.baseline_mm == pytest.approx(rig.baseline_mm, rel=b_tol)
    assert rotation_angle_deg(cal.rig.R.T @ rig.R) < r_tol
    cos = cal.rig.T @ rig.T / (np.linalg.norm(cal.rig.T) * np.linalg.norm(rig.T))
    assert math.degrees(math.acos(min(1.0, cos))) < 1.0


@pytest.fixture(scope="module")
def noisy_sets(rig):
    """10 stereo views per board kind, 2 grey levels of noise: board -> (left dets, right dets)."""
    return {b: detect_pairs(b, render_stereo(b, rig, stereo_board_poses(10), noise_sigma=2.0))
            for b in (CHESS, CHARUCO)}


@pytest.mark.parametrize("board", [CHESS, CHARUCO], ids=["chess", "charuco"])
def test_stereo_calibration_recovers_rig_from_noisy_views(rig, board, noisy_sets):
    views, skipped = pair_detections([f"{k:02d}" for k in range(10)], *noisy_sets[board], board)
    assert skipped == [] and len(views) == 10
    cal = calibrate_stereo(views, board, SIZE, SIZE)
    check_rig(cal, rig, board)
    assert cal.rms_px < 0.35 and cal.outliers == ()
    # The calibrated rig measures: a held-out view's corners, triangulated, keep the board's
    # true size within 0.5 % and its depth within 1 %.
    T = stereo_board_poses(11, seed=9)[-1]
    left, right = render_stereo(board, rig, [T], noise_sigma=2.0, seed=5)[0]
    dl, dr = detect_board(left, board), detect_board(right, board)
    ids = np.intersect1d(dl.ids, dr.ids)
    P = board_points_left(dl, dr, board, cal.rig)
    P_true = board.object_points()[ids] @ T[:3, :3].T + T[:3, 3]
    span = np.linalg.norm(P[-1] - P[0]) / np.linalg.norm(P_true[-1] - P_true[0])
    assert span == pytest.approx(1.0, abs=0.005)
    assert P[:, 2].mean() == pytest.approx(P_true[:, 2].mean(), rel=0.01)


def test_partly_missed_views_chessboard_skipped_charuco_used(rig):
    """A board partly out of the left image: the chessboard pair is named and skipped (all
    corners or nothing); the ChArUco pair is kept with the corners both cameras saw."""
    poses = stereo_board_poses(4, seed=2)
    poses.append(make_T(np.eye(3), np.array([60.0, -90.0, 520.0])))  # sticks out of the left image
    names = [f"v{k}" for k in range(5)]
    for board in (CHESS, CHARUCO):
        images = render_stereo(board, rig, poses, noise_sigma=1.0, seed=1)
        dl, dr = detect_pairs(board, images)
        views, skipped = pair_detections(names, dl, dr, board)
        if board is CHESS:
            assert skipped == [("v4", "board not found in the left image")]
            assert len(views) == 4
        else:
            assert skipped == [] and len(views) == 5
            partial = views[-1]
            assert 6 <= len(np.intersect1d(partial.left.ids, partial.right.ids)) < board.n_corners
        cal = calibrate_stereo(views, board, SIZE, SIZE)
        assert cal.rig.baseline_mm == pytest.approx(100.0, rel=0.02)


def test_outlier_view_is_flagged(noisy_sets):
    dl, dr = (list(d[:8]) for d in noisy_sets[CHESS])
    bad = dr[3]
    rng = np.random.default_rng(0)
    dr[3] = type(bad)(bad.ids, bad.image_points + rng.normal(0, 4.0, bad.image_points.shape))
    views, _ = pair_detections([f"p{k}" for k in range(8)], dl, dr, CHESS)
    cal = calibrate_stereo(views, CHESS, SIZE, SIZE)
    assert cal.outliers == ("p3",)
    assert cal.per_view_px[3, 1] > 2.0


def test_flag_outliers_rule():
    assert flag_outliers(np.array([0.2, 0.25, 0.3, 2.0])).tolist() == [False, False, False, True]
    # everything under the 1 px floor is fine even when one view is 3x the median
    assert not flag_outliers(np.array([0.1, 0.1, 0.1, 0.5])).any()


def test_too_few_views_is_input_error(noisy_sets):
    dl, dr = noisy_sets[CHESS]
    views, _ = pair_detections(["a", "b", "c"], dl[:3], dr[:3], CHESS)
    with pytest.raises(InputError, match="only 3 usable stereo pairs, need at least 4"):
        calibrate_stereo(views, CHESS, SIZE, SIZE)


def test_match_order_fixes_a_reversed_chessboard(rig):
    images = render_stereo(CHESS, rig, stereo_board_poses(1))
    dl, dr = detect_board(images[0][0], CHESS), detect_board(images[0][1], CHESS)
    flipped = reversed_order(dr, CHESS)
    fixed = match_order(dl, flipped, CHESS)
    assert np.allclose(fixed.image_points, dr.image_points)
    assert match_order(dl, dr, CHESS) is dr


# ----------------------------------------------------------------------------- hand-eye


def T_base_board_true() -> np.ndarray:
    """The board lying on a table 300 mm below the base origin, face up, 700 mm in front."""
    return make_T(np.diag([1.0, -1.0, -1.0]) @ cv2.Rodrigues(np.array([0.0, 0.0, 0.4]))[0],
                  np.array([700.0, 100.0, -300.0]))


def hand_eye_views(rig, T_base_flange, board=CHARUCO, noise=1.0):
    X = true_hand_eye()
    rng = np.random.default_rng(7)
    T_left_board = []
    for T_bf in T_base_flange:
        T_lb = np.linalg.inv(T_bf @ X) @ T_base_board_true()
        img = renderer(board, rig.left).render(T_lb[:3, :3], T_lb[:3, 3], rng=rng, noise_sigma=noise)
        det = detect_board(img, board)
        assert det is not None
        T_left_board.append(board_pose(det, board, rig.left)[0])
    return T_left_board


def test_hand_eye_recovers_camera_on_flange(rig):
    """Tolerance: the camera's position on the flange within 3 mm, its rotation within 0.3 deg,
    from 8 views with 1 grey-level noise and the true intrinsics."""
    T_bf = look_at_flange_poses(T_base_board_true(), true_hand_eye(), 8)
    res = calibrate_hand_eye(T_bf, hand_eye_views(rig, T_bf))
    X = true_hand_eye()
    assert np.linalg.norm(res.t - X[:3, 3]) < 3.0
    assert rotation_angle_deg(res.R.T @ X[:3, :3]) < 0.3
    assert res.warnings == ()
    assert res.position_residual_mm < 3.0 and res.rotation_residual_deg < 0.3
    assert np.linalg.norm(res.T_base_board[:3, 3] - T_base_board_true()[:3, 3]) < 5.0


def test_hand_eye_pure_translation_is_warned(rig):
    T_bf = look_at_flange_poses(T_base_board_true(), true_hand_eye(), 5, rotate=False)
    T_lb = hand_eye_views(rig, T_bf)
    with pytest.raises(InputError, match="vary too little in rotation"):
        calibrate_hand_eye(T_bf, T_lb)


def test_hand_eye_small_rotation_is_warned():
    rng = np.random.default_rng(2)
    X = true_hand_eye()
    T_bf = [make_T(cv2.Rodrigues(np.radians(rng.uniform(-3, 3, 3)))[0], rng.uniform(-50, 50, 3) + [600, 0, 300])
            for _ in range(5)]
    T_lb = [np.linalg.inv(T @ X) @ T_base_board_true() for T in T_bf]
    res = calibrate_hand_eye(T_bf, T_lb)
    assert 1.0 < res.max_rotation_deg < 10.0
    assert any("vary too little in rotation" in w for w in res.warnings)


def test_hand_eye_single_axis_is_warned():
    Rz = [cv2.Rodrigues(np.array([0.0, 0.0, a]))[0] for a in (0.0, 0.3, 0.6, 0.9)]
    T_bf = [make_T(R, np.array([500.0 + 10 * k, 0.0, 400.0])) for k, R in enumerate(Rz)]
    X = true_hand_eye()
    T_lb = [np.linalg.inv(T @ X) @ T_base_board_true() for T in T_bf]
    assert any("about one axis" in w for w in hand_eye_motion_warnings(T_bf)[0])
    with pytest.raises(InputError, match="no solution: all rotations between the flange poses are about one axis"):
        calibrate_hand_eye(T_bf, T_lb)  # Park's method cannot solve it


def test_hand_eye_input_errors():
    with pytest.raises(InputError, match="need at least 3"):
        calibrate_hand_eye([np.eye(4)] * 2, [np.eye(4)] * 2)
    with pytest.raises(InputError, match="unknown hand-eye method 'magic'"):
        calibrate_hand_eye([np.eye(4)] * 3, [np.eye(4)] * 3, method="magic")


# ----------------------------------------------------------------------------- water plane


@pytest.mark.parametrize("use_right", [True, False], ids=["triangulated", "pnp"])
def test_water_plane_from_floating_boards(rig, use_right):
    """Two boards floating on water at z = -350 mm (base), each tipped ~2 degrees by waves,
    seen from one flange pose: the plane height within 2 mm, tilt under 1.5 deg."""
    water_z = -350.0
    X = true_hand_eye()
    T_base_left = make_T(np.diag([1.0, -1.0, -1.0]), np.array([650.0, 0.0, water_z + 550.0]))
    T_bf = T_base_left @ np.linalg.inv(X)
    Rl, Rr = renderer(CHARUCO, rig.left), renderer(CHARUCO, rig.right)
    points = []
    for k, (dx, tip) in enumerate(((-200.0, [0.03, 0.0, 0.2]), (40.0, [-0.02, 0.03, -0.3]))):
        R_board = np.diag([1.0, -1.0, -1.0]) @ cv2.Rodrigues(np.array(tip))[0]
        centre = np.array([650.0 + dx, -60.0 + 20 * k, water_z])
        T_base_board = make_T(R_board, centre - R_board @ np.array([125.0, 87.5, 0.0]))
        T_lb = np.linalg.inv(T_base_left) @ T_base_board
        T_rb = make_T(rig.R, rig.T) @ T_lb
        dl = detect_board(Rl.render(T_lb[:3, :3], T_lb[:3, 3], noise_sigma=1.0), CHARUCO)
        dr = detect_board(Rr.render(T_rb[:3, :3], T_rb[:3, 3], noise_sigma=1.0), CHARUCO) if use_right else None
        assert dl is not None
        P_left = board_points_left(dl, dr, CHARUCO, rig)
        points.append(P_left @ (T_bf @ X)[:3, :3].T + (T_bf @ X)[:3, 3])
    plane = fit_water_plane(np.vstack(points))
    assert plane.z_mm == pytest.approx(water_z, abs=2.0)
    assert plane.tilt_deg < 1.5
    assert plane.normal[2] > 0


def test_water_plane_errors():
    with pytest.raises(InputError, match="need at least 3"):
        fit_water_plane(np.zeros((2, 3)))
    with pytest.raises(InputError, match="one line"):
        fit_water_plane(np.array([[0.0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3]]))


def test_water_plane_from_single_markers(rig):
    """Four 60 mm markers bobbing on water at z = -300 mm (each tipped up to ~3 deg), one of
    them outside the right camera's view: three triangulated, one by PnP; height within 2 mm."""
    from photoservo.vision.board import detect_markers
    from photoservo.vision.calibrate import marker_points_left

    water_z = -300.0
    T_base_left = make_T(np.diag([1.0, -1.0, -1.0]), np.array([600.0, 0.0, water_z + 520.0]))
    rng = np.random.default_rng(3)
    face_up = np.diag([1.0, -1.0, -1.0])
    spots = [(-50.0, -80.0), (90.0, -60.0), (20.0, 90.0), (-215.0, 40.0)]  # the last: left image only
    markers = [(k, 60.0, make_T(face_up @ cv2.Rodrigues(rng.uniform(-0.05, 0.05, 3))[0],
                                np.array([600.0 + x, y, water_z]))) for k, (x, y) in enumerate(spots)]
    left, right = render_markers(rig, T_base_left, markers)
    dl, dr = detect_markers(left), detect_markers(right)
    assert sorted(dl) == [0, 1, 2, 3] and 3 not in dr and {0, 1, 2} <= set(dr)
    P, n_tri, n_pnp = marker_points_left(dl, dr, 60.0, rig)
    assert (n_tri, n_pnp) == (3, 1)
    plane = fit_water_plane(P @ T_base_left[:3, :3].T + T_base_left[:3, 3])
    assert plane.z_mm == pytest.approx(water_z, abs=2.0)
    assert plane.tilt_deg < 2.0
