"""Calibration maths (issue "Calibration"): the stereo rig, the hand-eye transform and the water
plane, from board detections (`vision/board.py`) and flange poses. Pure: arrays in, value
objects out; no files, no devices.

Conventions (DESIGN.md, rig TOML): lengths in mm, OpenCV camera frames.
  stereo:    X_right  = R · X_left + T
  hand-eye:  X_flange = R_he · X_left + t_he
  poses:     T_a_b is 4x4 with X_a = T_a_b · X_b (T_base_flange from the arm, T_left_board from PnP)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.geometry import make_pose as make_T  # one builder for the whole of vision/
from photoservo.geometry import mean_rotation, rotation_angle_deg  # noqa: F401 (callers import them from here)
from photoservo.vision.board import (
    Board,
    BoardDetection,
    common_corners,
    marker_object_points,
    match_order,
)
from photoservo.vision.rig import Camera, Rig

MIN_STEREO_VIEWS = 4       # usable pairs needed for a stereo calibration
MIN_COMMON_CORNERS = 6     # corners seen in both images for a pair to count
OUTLIER_FACTOR = 3.0       # a view is an outlier when its error > FACTOR x the median ...
OUTLIER_FLOOR_PX = 1.0     # ... and > this many px
MIN_HAND_EYE_VIEWS = 3
MIN_ROTATION_DEG = 10.0    # hand-eye: the largest rotation between two poses must reach this
MIN_SOLVABLE_ROTATION_DEG = 1.0  # below this there is nothing to solve (an error, not a warning)
MIN_AXIS_SPREAD = 0.15     # hand-eye: 2nd/1st singular value of the motion axes (0 = one axis)
HAND_EYE_METHODS = {
    "tsai": cv2.CALIB_HAND_EYE_TSAI,
    "park": cv2.CALIB_HAND_EYE_PARK,
    "horaud": cv2.CALIB_HAND_EYE_HORAUD,
    "andreff": cv2.CALIB_HAND_EYE_ANDREFF,
    "daniilidis": cv2.CALIB_HAND_EYE_DANIILIDIS,
}


# ----------------------------------------------------------------------------- small pose helpers




# ----------------------------------------------------------------------------- stereo


@dataclass(frozen=True)
class StereoView:
    """One usable stereo pair: its name and the board as found in each image."""

    name: str
    left: BoardDetection
    right: BoardDetection


@dataclass(frozen=True)
class StereoCalibration:
    """Result of `calibrate_stereo`. `per_view_px` (n, 2): RMS reprojection error of each view
    in the left and right image (px), after the stereo fit; `rms_px`: over all views and both
    cameras; `rms_left_px` / `rms_right_px`: the single-camera calibrations. `outliers`: names
    of views whose error exceeds max(OUTLIER_FACTOR x median, OUTLIER_FLOOR_PX)."""

    rig: Rig
    names: tuple[str, ...]
    rms_px: float
    rms_left_px: float
    rms_right_px: float
    per_view_px: np.ndarray
    outliers: tuple[str, ...]


def pair_detections(names: Sequence[str], left: Sequence[BoardDetection | None],
                    right: Sequence[BoardDetection | None], board: Board
                    ) -> tuple[list[StereoView], list[tuple[str, str]]]:
    """Keep the pairs where the board is found in both images with >= MIN_COMMON_CORNERS
    shared corners (a plain chessboard's right order is matched to the left's, `match_order`).
    Returns (views, skipped) with skipped = [(name, reason)]."""
    views, skipped = [], []
    for name, dl, dr in zip(names, left, right):
        if dl is None or dr is None:
            side = "both images" if dl is None and dr is None else ("the left image" if dl is None else "the right image")
            skipped.append((name, f"board not found in {side}"))
            continue
        dr = match_order(dl, dr, board)
        n = int(np.intersect1d(dl.ids, dr.ids).size)
        if n < MIN_COMMON_CORNERS:
            skipped.append((name, f"only {n} corners seen in both images (need {MIN_COMMON_CORNERS})"))
            continue
        views.append(StereoView(name, dl, dr))
    return views, skipped


def _points(board: Board, views: Sequence[StereoView]) -> tuple[list, list, list]:
    obj, img_l, img_r = [], [], []
    P = board.object_points()
    for v in views:
        ids, uv_l, uv_r = common_corners(v.left, v.right)
        obj.append(P[ids].astype(np.float32).reshape(-1, 1, 3))
        img_l.append(uv_l.astype(np.float32).reshape(-1, 1, 2))
        img_r.append(uv_r.astype(np.float32).reshape(-1, 1, 2))
    return obj, img_l, img_r


def flag_outliers(errors_px: np.ndarray) -> np.ndarray:
    """Boolean mask of outlier views: error > max(OUTLIER_FACTOR x median, OUTLIER_FLOOR_PX)."""
    e = np.asarray(errors_px, dtype=np.float64)
    return e > max(OUTLIER_FACTOR * float(np.median(e)), OUTLIER_FLOOR_PX)


def calibrate_stereo(views: Sequence[StereoView], board: Board, size_left: tuple[int, int],
                     size_right: tuple[int, int], fix_k3: bool = True) -> StereoCalibration:
    """Calibrate both cameras (cv2.calibrateCamera on the corners each pair shares) and the
    extrinsics (cv2.stereoCalibrate with the intrinsics fixed, then refined jointly — the joint
    result is kept when its RMS is no worse). Distortion: k1 k2 p1 p2 k3, k3 held at 0 when
    `fix_k3` (few views cannot determine it for ordinary lenses). T comes out in the board's
    unit, mm.

    Raises:
        InputError: fewer than MIN_STEREO_VIEWS views.
    """
    if len(views) < MIN_STEREO_VIEWS:
        raise InputError(f"only {len(views)} usable stereo pairs, need at least {MIN_STEREO_VIEWS}")
    obj, img_l, img_r = _points(board, views)
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    cams, rms = [], []
    for img, size in ((img_l, size_left), (img_r, size_right)):
        out = cv2.calibrateCameraExtended(obj, img, size, None, None, flags=flags)
        rms.append(float(out[0]))
        cams.append((out[1], out[2].ravel()[:5]))
    (K1, d1), (K2, d2) = cams
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-7)  # 200 / 1e-9: 3x slower, same result
    fixed = cv2.stereoCalibrateExtended(obj, img_l, img_r, K1, d1, K2, d2, size_left, None, None,
                                        flags=cv2.CALIB_FIX_INTRINSIC, criteria=crit)
    joint = cv2.stereoCalibrateExtended(obj, img_l, img_r, K1.copy(), d1.copy(), K2.copy(), d2.copy(),
                                        size_left, fixed[5].copy(), fixed[6].copy(),
                                        flags=cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_USE_EXTRINSIC_GUESS | flags,
                                        criteria=crit)
    best = joint if np.isfinite(joint[0]) and joint[0] <= fixed[0] else fixed
    rms_px, K1, d1, K2, d2, R, T = best[:7]
    per_view = np.asarray(best[11], dtype=np.float64).reshape(-1, 2)
    rig = Rig(
        left=Camera(size=tuple(size_left), K=np.asarray(K1, float), dist=np.asarray(d1, float).ravel()[:5]),
        right=Camera(size=tuple(size_right), K=np.asarray(K2, float), dist=np.asarray(d2, float).ravel()[:5]),
        R=np.asarray(R, float), T=np.asarray(T, float).ravel(),
    )
    mask = flag_outliers(per_view.max(axis=1))
    names = tuple(v.name for v in views)
    return StereoCalibration(rig=rig, names=names, rms_px=float(rms_px), rms_left_px=rms[0],
                             rms_right_px=rms[1], per_view_px=per_view,
                             outliers=tuple(n for n, m in zip(names, mask) if m))


# ----------------------------------------------------------------------------- board pose


def board_pose(det: BoardDetection, board: Board, cam: Camera) -> tuple[np.ndarray, float]:
    """Pose of the board in a calibrated camera, T_cam_board (4x4, mm), by PnP (IPPE for a
    plane, then Levenberg-Marquardt refinement), and its RMS reprojection error (px)."""
    return plane_pose(board.object_points()[det.ids], det.image_points, cam)


def plane_pose(P: np.ndarray, uv: np.ndarray, cam: Camera) -> tuple[np.ndarray, float]:
    """PnP of >= 4 coplanar points P (n, 3) (z = 0, mm) seen at uv (n, 2) px: T_cam_plane and
    the RMS reprojection error (px)."""
    P = np.ascontiguousarray(P, dtype=np.float64)
    uv = np.ascontiguousarray(uv, dtype=np.float64)
    ok, rvec, tvec = cv2.solvePnP(P, uv, cam.K, cam.dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        ok, rvec, tvec = cv2.solvePnP(P, uv, cam.K, cam.dist, flags=cv2.SOLVEPNP_ITERATIVE)
    rvec, tvec = cv2.solvePnPRefineLM(P, uv, cam.K, cam.dist, rvec, tvec)
    proj, _ = cv2.projectPoints(P, rvec, tvec, cam.K, cam.dist)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - uv) ** 2, axis=1))))
    return make_T(cv2.Rodrigues(rvec)[0], tvec.ravel()), rms


# ----------------------------------------------------------------------------- hand-eye


@dataclass(frozen=True)
class HandEyeResult:
    """Result of `calibrate_hand_eye`: X_flange = R · X_left + t (t in mm).

    Residuals are the spread of the board's pose in the base frame over the views (it is fixed
    in the world, so with a perfect calibration every view places it identically):
    `position_residual_mm` RMS distance of the board origin from its mean, `rotation_residual_deg`
    RMS angle from the mean orientation. `max_rotation_deg`: the largest rotation between two
    flange poses. `warnings`: degenerate-motion messages (see `hand_eye_motion_warnings`)."""

    R: np.ndarray
    t: np.ndarray
    position_residual_mm: float
    rotation_residual_deg: float
    max_rotation_deg: float
    T_base_board: np.ndarray
    warnings: tuple[str, ...]


def hand_eye_motion_warnings(T_base_flange: Sequence[np.ndarray]) -> tuple[list[str], float]:
    """Why a set of flange poses may not determine the hand-eye transform (AX = XB needs at
    least two motions with non-parallel rotation axes): (messages, largest rotation in deg).

    Warns when no two poses differ by MIN_ROTATION_DEG or more (pure or nearly pure
    translation: the rotation and the translation of the camera on the flange are then
    undetermined), and when all rotations between poses share one axis (spread < MIN_AXIS_SPREAD:
    the translation along that axis is undetermined)."""
    msgs: list[str] = []
    axes, max_angle = [], 0.0
    n = len(T_base_flange)
    for i in range(n):
        for j in range(i + 1, n):
            R_ij = T_base_flange[i][:3, :3].T @ T_base_flange[j][:3, :3]
            rv = cv2.Rodrigues(R_ij)[0].ravel()
            angle = math.degrees(float(np.linalg.norm(rv)))
            max_angle = max(max_angle, angle)
            if angle > 2.0:
                axes.append(rv / np.linalg.norm(rv))
    if max_angle < MIN_ROTATION_DEG:
        msgs.append(f"the flange poses vary too little in rotation (largest {max_angle:.1f} deg between two "
                    f"poses, need >= {MIN_ROTATION_DEG:.0f}): the hand-eye transform is not determined; "
                    f"tilt the arm about two different axes between views")
    elif len(axes) >= 2:
        s = np.linalg.svd(np.array(axes), compute_uv=False)
        if s[1] / s[0] < MIN_AXIS_SPREAD:
            msgs.append("all rotations between the flange poses are about one axis: the camera's offset "
                        "along that axis is not determined; add views rotated about another axis")
    return msgs, max_angle


def calibrate_hand_eye(T_base_flange: Sequence[np.ndarray], T_left_board: Sequence[np.ndarray],
                       method: str = "park") -> HandEyeResult:
    """Eye-in-hand calibration: the left camera on the flange, a board fixed in the world seen
    in each view. Solves AX = XB with cv2.calibrateHandEye (gripper = flange, target = board):
    X = T_flange_left. Default method Park & Martin: as accurate as Tsai & Lenz on the rendered
    views, and OpenCV's Tsai refuses sets whose motions rotate less than ~15 degrees. Residuals
    as in `HandEyeResult`.

    Raises:
        InputError: too few views, an unknown method, poses that rotate less than
            MIN_SOLVABLE_ROTATION_DEG (pure translation), or no solution from OpenCV.
    """
    n = len(T_base_flange)
    if n != len(T_left_board):
        raise InputError(f"{n} flange poses but {len(T_left_board)} board poses")
    if n < MIN_HAND_EYE_VIEWS:
        raise InputError(f"only {n} hand-eye views with the board found, need at least {MIN_HAND_EYE_VIEWS}")
    if method not in HAND_EYE_METHODS:
        raise InputError(f"unknown hand-eye method '{method}' (choose {', '.join(HAND_EYE_METHODS)})")
    warnings, max_angle = hand_eye_motion_warnings(T_base_flange)
    if max_angle < MIN_SOLVABLE_ROTATION_DEG:  # nothing to solve: OpenCV would return I, 0
        raise InputError(warnings[0])
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)  # it logs instead of raising
    try:
        R_he, t_he = cv2.calibrateHandEye(
            [T[:3, :3] for T in T_base_flange], [T[:3, 3] for T in T_base_flange],
            [T[:3, :3] for T in T_left_board], [T[:3, 3] for T in T_left_board],
            method=HAND_EYE_METHODS[method])
    finally:
        cv2.utils.logging.setLogLevel(level)
    R_he, t_he = np.asarray(R_he, float), np.asarray(t_he, float).ravel()
    failed = np.array_equal(R_he, np.eye(3)) and not np.any(t_he)  # OpenCV's "not enough motion" answer
    if failed or not (np.all(np.isfinite(R_he)) and np.all(np.isfinite(t_he))) or abs(np.linalg.det(R_he) - 1) > 1e-3:
        raise InputError("hand-eye calibration found no solution" + (f": {warnings[0]}" if warnings else ""))
    X = make_T(R_he, t_he)
    boards = [T_bf @ X @ T_lb for T_bf, T_lb in zip(T_base_flange, T_left_board)]
    p = np.array([B[:3, 3] for B in boards])
    R_mean = mean_rotation([B[:3, :3] for B in boards])
    pos_res = float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1))))
    rot_res = float(np.sqrt(np.mean([rotation_angle_deg(R_mean.T @ B[:3, :3]) ** 2 for B in boards])))
    return HandEyeResult(R=R_he, t=t_he, position_residual_mm=pos_res, rotation_residual_deg=rot_res,
                         max_rotation_deg=max_angle, T_base_board=make_T(R_mean, p.mean(axis=0)),
                         warnings=tuple(warnings))


# ----------------------------------------------------------------------------- water plane


def triangulate(rig: Rig, uv_left: np.ndarray, uv_right: np.ndarray) -> np.ndarray:
    """Points seen in both images -> (n, 3) positions in the left-camera frame (mm): undistort
    to normalised coordinates, then linear triangulation with P_left = [I | 0],
    P_right = [R | T]."""
    xl = cv2.undistortPoints(uv_left.reshape(-1, 1, 2).astype(np.float64), rig.left.K, rig.left.dist)
    xr = cv2.undistortPoints(uv_right.reshape(-1, 1, 2).astype(np.float64), rig.right.K, rig.right.dist)
    P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = np.hstack([rig.R, rig.T.reshape(3, 1)])
    Xh = cv2.triangulatePoints(P1, P2, xl.reshape(-1, 2).T, xr.reshape(-1, 2).T)
    return (Xh[:3] / Xh[3]).T


def board_points_left(left: BoardDetection | None, right: BoardDetection | None, board: Board,
                      rig: Rig) -> np.ndarray:
    """Board corners in the left-camera frame (n, 3) mm: triangulated from both cameras on the
    corners both saw (>= MIN_COMMON_CORNERS; independent of the printed size), else from the
    left camera's PnP pose of the board (needs the true square size). Empty when not seen."""
    if left is not None and right is not None:
        ids, uv_l, uv_r = common_corners(left, right)
        if ids.size >= MIN_COMMON_CORNERS:
            return triangulate(rig, uv_l, uv_r)
    if left is not None:
        T, _ = board_pose(left, board, rig.left)
        P = board.object_points()[left.ids]
        return P @ T[:3, :3].T + T[:3, 3]
    return np.zeros((0, 3))


def marker_points_left(left: dict[int, np.ndarray], right: dict[int, np.ndarray] | None, side_mm: float,
                       rig: Rig) -> tuple[np.ndarray, int, int]:
    """Corners of single square markers in the left-camera frame (n, 3) mm: triangulated when
    both cameras see a marker, else from the left camera's PnP of its 4 corners (needs the true
    `side_mm`). Returns (points, markers triangulated, markers from PnP)."""
    pts, n_tri, n_pnp = [], 0, 0
    P = marker_object_points(side_mm)
    for marker_id, uv_l in sorted(left.items()):
        if right is not None and marker_id in right:
            pts.append(triangulate(rig, uv_l, right[marker_id]))
            n_tri += 1
        else:
            T, _ = plane_pose(P, uv_l, rig.left)
            pts.append(P @ T[:3, :3].T + T[:3, 3])
            n_pnp += 1
    return (np.vstack(pts) if pts else np.zeros((0, 3))), n_tri, n_pnp


@dataclass(frozen=True)
class WaterPlane:
    """The water surface in the base frame: least-squares plane through the floating boards'
    corners. `z_mm`: the plane's height at the points' centroid (the number the tracker uses
    for a level surface); `normal`: unit normal (pointing up, n_z > 0); `tilt_deg`: angle
    between the normal and the base z axis; `rms_mm`: RMS distance of the points from the
    plane; `n_points`, `centroid` (mm)."""

    z_mm: float
    normal: np.ndarray
    tilt_deg: float
    rms_mm: float
    n_points: int
    centroid: np.ndarray


def fit_water_plane(points_base: np.ndarray) -> WaterPlane:
    """Total-least-squares plane through (n, 3) base-frame points (SVD of the centred points).

    Raises:
        InputError: fewer than 3 points, or all on one line.
    """
    P = np.asarray(points_base, dtype=np.float64).reshape(-1, 3)
    if len(P) < 3:
        raise InputError(f"water plane: only {len(P)} marker points found, need at least 3")
    c = P.mean(axis=0)
    _, s, Vt = np.linalg.svd(P - c)
    if s[1] < 1e-6 * max(s[0], 1e-12):
        raise InputError("water plane: all marker points lie on one line")
    n = Vt[2] if Vt[2, 2] >= 0 else -Vt[2]
    d = (P - c) @ n
    return WaterPlane(z_mm=float(c[2]), normal=n, tilt_deg=math.degrees(math.acos(min(1.0, abs(float(n[2]))))),
                      rms_mm=float(np.sqrt(np.mean(d**2))), n_points=len(P), centroid=c)
