"""photoservo calibrate — the stereo rig, the hand-eye transform and the water plane.

    photoservo calibrate board   --board 9x6 --square-mm 25 [--charuco] --out board.png
    photoservo calibrate capture --devices 0 1 --out calib/ [--interval 2 | Enter] [--port /dev/ttyUSB0]
    photoservo calibrate stereo  --left calib/left --right calib/right --board 9x6 --square-mm 25 --out rig.toml
    photoservo calibrate hand-eye --rig rig.toml --views calib/ --poses calib/poses.csv --board 9x6 --square-mm 25
    photoservo calibrate water   --rig rig.toml --views water/ --poses water/poses.csv --board 9x6 --square-mm 25

COLSxROWS counts INNER corners (where four squares meet): a board of 10 x 7 squares is 9x6.

Flange poses CSV (hand-eye, water; written by `calibrate capture --port`): a header row, then one
row per view; `name` is the image's file name with or without its extension. Either
    name,x_mm,y_mm,z_mm,rx_rad,ry_rad,rz_rad   T_base_flange: position (mm) and rotation vector
                                               (axis x angle, rad) of the flange in the base frame
or  name,q1_rad,...,q7_rad                     PA-10 joint angles, converted with pa10.fk
(when both are present the pose columns are used).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import math
import re
import sys
import threading
import time
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.fileio import read_image, write_image_atomic, write_text_atomic
from photoservo.robot.link import Link, LinkError
from photoservo.cli.options import add_config_options
from photoservo.config import load_config
from photoservo.tomlconf import configs_dir, read_toml
from photoservo.vision.board import (
    DEFAULT_DICTIONARY,
    Board,
    BoardDetection,
    board_texture,
    detect_board,
    detect_markers,
    draw_detection,
)
from photoservo.vision.calibrate import (
    MIN_COMMON_CORNERS,
    MIN_HAND_EYE_VIEWS,
    MIN_ROTATION_DEG,
    board_points_left,
    board_pose,
    calibrate_hand_eye,
    calibrate_stereo,
    fit_water_plane,
    make_T,
    marker_points_left,
    pair_detections,
    rotation_angle_deg,
)
from photoservo.vision.rig import Rig, load_rig, save_rig
from photoservo.vision.sources import (
    IMAGE_SUFFIXES,
    CamerasParams,
    SourceConfig,
    StereoSource,
    make_source,
    source_config,
)

POSE_COLUMNS = ("x_mm", "y_mm", "z_mm", "rx_rad", "ry_rad", "rz_rad")
JOINT_COLUMNS = tuple(f"q{i}_rad" for i in range(1, 8))
LIVE_TIMEOUT_S = 30.0  # water --live gives up when the board is not seen for this long
BOARD_HELP = "board size as COLSxROWS INNER corners (where four squares meet): 10 x 7 squares -> 9x6"


# ----------------------------------------------------------------------------- arguments


def _board_options(p: argparse.ArgumentParser, required: bool = True) -> None:
    p.add_argument("--board", required=required, metavar="COLSxROWS", help=BOARD_HELP)
    p.add_argument("--square-mm", type=float, required=required, metavar="S", help="square side (mm), as printed")
    p.add_argument("--charuco", action="store_true", help="a ChArUco board (markers in the white squares)")
    p.add_argument("--marker-mm", type=float, default=0.0, metavar="M",
                   help="ChArUco marker side (mm); default 0.7 x square")
    p.add_argument("--dict", default=DEFAULT_DICTIONARY, metavar="NAME",
                   help=f"ChArUco ArUco dictionary (default {DEFAULT_DICTIONARY}; also finds DICT_4X4_50/100 boards)")


def _source_options(p: argparse.ArgumentParser) -> None:
    """Stereo source flags; each overrides its key of the config's [cameras] section."""
    src = p.add_mutually_exclusive_group()
    src.add_argument("--devices", nargs=2, metavar=("LEFT", "RIGHT"), help="two OpenCV devices: index or path")
    src.add_argument("--side-by-side", metavar="DEVICE", help="one device with left|right halves")
    src.add_argument("--videos", nargs=2, metavar=("LEFT", "RIGHT"), help="two video files")
    src.add_argument("--folders", nargs=2, metavar=("LEFT", "RIGHT"), help="two image folders")
    p.add_argument("--width", type=int, help="capture width (px per camera; 0 = device default)")
    p.add_argument("--height", type=int)
    p.add_argument("--fps", type=float)
    p.add_argument("--fourcc", help="e.g. MJPG")
    p.add_argument("--exposure", type=float, help="lock exposure (device units; 0 = automatic)")
    p.add_argument("--white-balance-k", type=float, help="lock white balance (K; 0 = automatic)")
    p.add_argument("--max-skew-ms", type=float, help="drop pairs whose left/right times differ more")


def _cameras(args: argparse.Namespace, cams: CamerasParams) -> SourceConfig:
    """[cameras] with the command line's source flags on top -> the source's config."""
    kind = {"devices": "devices", "side_by_side": "side_by_side", "videos": "videos", "folders": "folders"}
    changes: dict = {}
    for flag, k in kind.items():
        v = getattr(args, flag)
        if v:
            left, right = (v, "") if isinstance(v, str) else v
            changes.update(kind=k, left=left, right=right, realtime=True)
    for k in ("width", "height", "fps", "fourcc", "exposure", "white_balance_k", "max_skew_ms"):
        if getattr(args, k) is not None:
            changes[k] = getattr(args, k)
    cams = dataclasses.replace(cams, **changes)
    cams.validate("cameras")
    cfg = source_config(cams)
    if cfg is None:
        raise InputError("no cameras: give --devices, --side-by-side, --videos or --folders, "
                         "or set [cameras] kind in the config")
    return cfg


def _board(args: argparse.Namespace) -> Board:
    return Board.parse(args.board, args.square_mm, args.charuco, args.marker_mm, args.dict)


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)

    b = sub.add_parser("board", help="write a printable board image",
                       description="Write a printable calibration board (PNG) at a given resolution.")
    _board_options(b)
    b.add_argument("--out", required=True, metavar="BOARD.png")
    b.add_argument("--dpi", type=float, default=300.0, help="print resolution (default 300)")

    s = sub.add_parser("stereo", help="calibrate both cameras and the stereo extrinsics",
                       description="Calibrate the stereo rig from image pairs of a board (paired by file "
                                   "name). " + BOARD_HELP + ".")
    s.add_argument("--left", required=True, metavar="DIR", help="left camera images")
    s.add_argument("--right", required=True, metavar="DIR", help="right camera images (same file names)")
    _board_options(s)
    s.add_argument("--out", default="rig.toml", metavar="RIG.toml", help="rig file to write (default rig.toml)")
    s.add_argument("--free-k3", action="store_true", help="also fit k3 (wide-angle lenses; needs many views)")
    s.add_argument("--drop-outliers", action="store_true", help="calibrate again without the outlier views")

    h = sub.add_parser("hand-eye", help="the left camera's pose on the flange",
                       description="Eye-in-hand calibration: a board fixed in the world, seen by the left "
                                   "camera from several flange poses -> the rig's [hand_eye]. Pose CSV "
                                   "columns: name,x_mm,y_mm,z_mm,rx_rad,ry_rad,rz_rad (T_base_flange, "
                                   "rotation vector) or name,q1_rad..q7_rad (PA-10 joints).")
    h.add_argument("--rig", required=True, metavar="RIG.toml")
    h.add_argument("--views", required=True, metavar="DIR", help="left images (DIR or DIR/left)")
    h.add_argument("--poses", metavar="POSES.csv", help="flange poses (default DIR/poses.csv)")
    _board_options(h)
    h.add_argument("--method", default="park", choices=["park", "tsai", "horaud", "andreff", "daniilidis"],
                   help="cv2.calibrateHandEye method (default park: as accurate as tsai on the test views, "
                        "and tsai gives up on motions that rotate less than ~15 deg)")
    h.add_argument("--out", metavar="RIG.toml", help="rig file to write (default: update --rig)")
    h.add_argument("--force", action="store_true",
                   help=f"write the result even when the poses rotate less than {MIN_ROTATION_DEG:.0f} deg")

    w = sub.add_parser("water", help="the water surface height in the base frame",
                       description="Fit the water plane to a board or single ArUco markers (--markers) "
                                   "floating on it, seen by the calibrated rig (with [hand_eye]) from known "
                                   "flange poses. One view of one board or of three markers is enough; "
                                   "markers spread out give the tilt too.")
    w.add_argument("--rig", required=True, metavar="RIG.toml")
    w.add_argument("--views", metavar="DIR", help="DIR/left (+ DIR/right) images, or DIR")
    w.add_argument("--poses", metavar="POSES.csv", help="flange poses (default DIR/poses.csv)")
    w.add_argument("--markers", type=float, metavar="SIDE_MM",
                   help="single ArUco markers of this side (mm, black square) from --dict instead of a board")
    w.add_argument("--live", action="store_true",
                   help="measure now: read pairs from the cameras ([cameras] or the source flags) and the "
                        "flange pose from the arm (--port) instead of --views")
    w.add_argument("--frames", type=int, default=5, metavar="N",
                   help="--live: pairs with the board found to use (default 5; gives up after 30 s)")
    w.add_argument("--port", help="--live: serial port of the arm's bridge")
    _source_options(w)
    add_config_options(w)
    _board_options(w, required=False)
    w.add_argument("--update", metavar="CFG.toml", help="write the height into this config file")
    w.add_argument("--key", default="tracker.water_z_mm", metavar="SECTION.KEY",
                   help="config key for --update (default tracker.water_z_mm)")

    c = sub.add_parser("capture", help="save synchronised pairs (and flange poses) for calibration",
                       description="Save stereo pairs from cameras, videos or folders, at an interval or "
                                   "on Enter ('q' + Enter ends), with a live preview in Rerun (corners "
                                   "drawn when --board is given). With --port, the flange pose at each "
                                   "pair's capture time goes to OUT/poses.csv.")
    _source_options(c)
    c.add_argument("--out", required=True, metavar="DIR", help="writes DIR/left, DIR/right, DIR/capture.csv")
    c.add_argument("--interval", type=float, default=0.0, metavar="S", help="save every S seconds (0: on Enter)")
    c.add_argument("--count", type=int, default=0, metavar="N", help="stop after N pairs (0: until q / end)")
    c.add_argument("--board", metavar="COLSxROWS", help="draw the found corners in the preview; " + BOARD_HELP)
    c.add_argument("--square-mm", type=float, default=25.0)
    c.add_argument("--charuco", action="store_true")
    c.add_argument("--marker-mm", type=float, default=0.0)
    c.add_argument("--dict", default=DEFAULT_DICTIONARY)
    c.add_argument("--require-board", action="store_true", help="save only pairs with the board in both images")
    c.add_argument("--port", help="serial port of the arm's bridge: log the flange pose of each pair")
    add_config_options(c)
    view = c.add_mutually_exclusive_group()
    view.add_argument("--spawn", action="store_true", help="spawn a Rerun viewer for the preview")
    view.add_argument("--connect", metavar="URL", help="stream the preview to a running viewer")
    c.add_argument("--save", metavar="PREVIEW.rrd", help="also write the preview recording here")


def run(args: argparse.Namespace) -> int:
    return {
        "board": run_board,
        "stereo": run_stereo,
        "hand-eye": run_hand_eye,
        "water": run_water,
        "capture": run_capture,
    }[args.action](args)


# ----------------------------------------------------------------------------- shared helpers


def image_files(folder: Path, what: str) -> dict[str, Path]:
    """Images in a folder by file name (sorted)."""
    if not folder.is_dir():
        raise InputError(f"{what} {folder}: folder not found")
    files = {p.name: p for p in sorted(folder.iterdir()) if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES}
    if not files:
        raise InputError(f"{what} {folder}: no images (.png, .jpg, ...) in the folder")
    return files


def _read_sized(path: Path, size: tuple[int, int] | None, what: str) -> np.ndarray:
    img = read_image(path, what)
    if size is not None and (img.shape[1], img.shape[0]) != tuple(size):
        raise InputError(f"{path}: image is {img.shape[1]}x{img.shape[0]}, expected {size[0]}x{size[1]} ({what})")
    return img


def _float(row: dict, col: str, where: str) -> float:
    try:
        v = float(row[col])
    except (TypeError, ValueError):
        raise InputError(f"{where}: column '{col}' is not a number: {row.get(col)!r}") from None
    if not math.isfinite(v):
        raise InputError(f"{where}: column '{col}' is not finite")
    return v


def read_flange_poses(path: Path) -> dict[str, np.ndarray]:
    """The flange poses CSV (module docstring) -> {name stem: T_base_flange (4x4, mm)}."""
    try:
        text = path.read_text()
    except OSError as e:
        raise InputError(f"{path}: cannot read poses file ({e.strerror or e})") from None
    reader = csv.DictReader(text.splitlines())
    cols = [c.strip() for c in (reader.fieldnames or [])]
    reader.fieldnames = cols
    if "name" not in cols:
        raise InputError(f"{path}: needs a header row with a 'name' column")
    use_pose = all(c in cols for c in POSE_COLUMNS)
    if not use_pose and not all(c in cols for c in JOINT_COLUMNS):
        raise InputError(f"{path}: needs columns {','.join(POSE_COLUMNS)} or {','.join(JOINT_COLUMNS)}")
    fk = None
    if not use_pose:
        from photoservo.robot.pa10 import fk
    poses: dict[str, np.ndarray] = {}
    for line, row in enumerate(reader, start=2):
        where = f"{path} line {line}"
        name = Path((row.get("name") or "").strip()).stem
        if not name:
            raise InputError(f"{where}: empty name")
        if use_pose:
            v = [_float(row, c, where) for c in POSE_COLUMNS]
            poses[name] = make_T(cv2.Rodrigues(np.array(v[3:]))[0], np.array(v[:3]))
        else:
            poses[name] = np.asarray(fk(np.array([_float(row, c, where) for c in JOINT_COLUMNS])), dtype=np.float64)
    if not poses:
        raise InputError(f"{path}: no pose rows")
    return poses


def pose_row(T_base_flange: np.ndarray) -> list[str]:
    """x_mm..rz_rad columns of a flange pose (as `read_flange_poses` reads them)."""
    rv = cv2.Rodrigues(T_base_flange[:3, :3])[0].ravel()
    return [f"{v:.6f}" for v in (*T_base_flange[:3, 3], *rv)]


def _views_dir(views: Path, side: str) -> Path | None:
    """DIR/left (or DIR/right); for the left side, DIR itself when it has no left/ subfolder."""
    if (views / side).is_dir():
        return views / side
    return views if side == "left" and views.is_dir() else None


def _posed_views(args: argparse.Namespace, rig: Rig, detect: Callable[[np.ndarray], Any], want_right: bool
                 ) -> list[tuple[str, np.ndarray, Any, Any]]:
    """(name, T_base_flange, left detection, right detection) for each pose row with an image;
    `detect(image)` finds the target (None when absent)."""
    views = Path(args.views)
    left_dir = _views_dir(views, "left")
    if left_dir is None:
        raise InputError(f"--views {views}: folder not found")
    poses = read_flange_poses(Path(args.poses) if args.poses else views / "poses.csv")
    left = {Path(n).stem: p for n, p in image_files(left_dir, "--views").items()}
    right_dir = _views_dir(views, "right") if want_right else None
    right = {Path(n).stem: p for n, p in image_files(right_dir, "--views right").items()} if right_dir else {}
    out = []
    for name, T in poses.items():
        if name not in left:
            print(f"  {name}: no image in {left_dir}, skipped")
            continue
        dl = detect(_read_sized(left[name], rig.left.size, "left image"))
        dr = detect(_read_sized(right[name], rig.right.size, "right image")) if name in right else None
        out.append((name, T, dl, dr))
    return out


def _live_views(args: argparse.Namespace, rig: Rig, detect: Callable[[np.ndarray], Any]
                ) -> list[tuple[str, np.ndarray, Any, Any]]:
    """`--frames` pairs with the board in the left image, each with the flange pose at its
    capture time from the arm's link (forward kinematics of the interpolated joint state)."""
    from photoservo.robot.pa10 import fk

    if not args.port:
        raise InputError("--live needs --port (the arm's bridge) for the flange pose")
    if args.frames < 1:
        raise InputError(f"--frames must be >= 1, got {args.frames}")
    config = load_config(args.config, args.overrides)
    source = make_source(_cameras(args, config.cameras))
    try:
        return _read_live(args, rig, detect, Link(args.port, config.link), source, fk)
    except LinkError as e:
        raise InputError(f"--port {args.port}: {e}") from None


def _read_live(args: argparse.Namespace, rig: Rig, detect: Callable[[np.ndarray], Any], link: Link, source: StereoSource,
               fk: Callable[[np.ndarray], np.ndarray]) -> list:
    out: list = []
    with link, source:
        deadline = time.monotonic() + LIVE_TIMEOUT_S
        for frame in source:
            if time.monotonic() > deadline:
                break
            if (frame.left.shape[1], frame.left.shape[0]) != tuple(rig.left.size):
                raise InputError(f"camera image is {frame.left.shape[1]}x{frame.left.shape[0]}, the rig's left "
                                 f"camera is {rig.left.size[0]}x{rig.left.size[1]}")
            dl = detect(frame.left)
            if dl is None:
                continue
            try:
                q = link.state_at(frame.t).q
            except LookupError:
                continue
            out.append((f"frame {frame.index}", np.asarray(fk(q), dtype=np.float64), dl, detect(frame.right)))
            if len(out) >= args.frames:
                break
        print(f"  {source.stats.summary()}")
    if not out:
        raise InputError(f"--live: the target was not found in the left camera within {LIVE_TIMEOUT_S:.0f} s")
    return out


# ----------------------------------------------------------------------------- board


def run_board(args: argparse.Namespace) -> int:
    board = _board(args)
    if not args.dpi > 0:
        raise InputError(f"--dpi must be > 0, got {args.dpi}")
    img, _ = board_texture(board, args.dpi / 25.4)
    write_image_atomic(args.out, img)
    w, h = img.shape[1] * 25.4 / args.dpi, img.shape[0] * 25.4 / args.dpi
    print(f"wrote {args.out}: {board.cols}x{board.rows} inner corners, {board.square_mm} mm squares"
          f"{' (ChArUco ' + board.dictionary + ')' if board.charuco else ''}; print at {args.dpi:g} dpi, "
          f"no scaling: {w:.0f} x {h:.0f} mm. Measure a square after printing and pass that as --square-mm.")
    return 0


# ----------------------------------------------------------------------------- stereo


def run_stereo(args: argparse.Namespace) -> int:
    board = _board(args)
    left = image_files(Path(args.left), "--left")
    right = image_files(Path(args.right), "--right")
    names = [n for n in left if n in right]
    if not names:
        raise InputError(f"--left {args.left} and --right {args.right}: no image name is in both folders")
    only = sorted(set(left) ^ set(right))
    if only:
        print(f"unpaired images (in one folder only), skipped: {', '.join(only)}")
    size_l = size_r = None
    det_l, det_r = [], []
    for n in names:
        il = _read_sized(left[n], size_l, "left image")
        ir = _read_sized(right[n], size_r, "right image")
        size_l, size_r = (il.shape[1], il.shape[0]), (ir.shape[1], ir.shape[0])
        det_l.append(detect_board(il, board))
        det_r.append(detect_board(ir, board))
    views, skipped = pair_detections(names, det_l, det_r, board)
    for name, why in skipped:
        print(f"  {name}: skipped, {why}")
    if board.is_symmetric:
        print(f"note: a {board.cols}x{board.rows} chessboard looks the same turned by 180 degrees; "
              "a board with one odd and one even corner count avoids order flips")
    cal = calibrate_stereo(views, board, size_l, size_r, fix_k3=not args.free_k3)
    _print_stereo(cal)
    if args.drop_outliers and cal.outliers:
        keep = [v for v in views if v.name not in cal.outliers]
        print(f"calibrating again without {len(cal.outliers)} outlier view(s)")
        cal = calibrate_stereo(keep, board, size_l, size_r, fix_k3=not args.free_k3)
        _print_stereo(cal)
    save_rig(cal.rig, args.out)
    print(f"wrote {args.out}")
    return 0


def _print_stereo(cal) -> None:
    print(f"{'view':<20} {'left px':>8} {'right px':>8}")
    for name, (el, er) in zip(cal.names, cal.per_view_px):
        flag = "  OUTLIER" if name in cal.outliers else ""
        print(f"{name:<20} {el:8.3f} {er:8.3f}{flag}")
    r = cal.rig
    print(f"reprojection RMS: stereo {cal.rms_px:.3f} px over {len(cal.names)} pairs "
          f"(left alone {cal.rms_left_px:.3f}, right alone {cal.rms_right_px:.3f})")
    for side, cam in (("left", r.left), ("right", r.right)):
        d = ", ".join(f"{x:.4f}" for x in cam.dist)
        print(f"{side:>5}: fx {cam.K[0, 0]:.2f}  fy {cam.K[1, 1]:.2f}  cx {cam.K[0, 2]:.2f}  "
              f"cy {cam.K[1, 2]:.2f}  dist [{d}]")
    print(f"stereo: baseline {r.baseline_mm:.2f} mm, T = [{r.T[0]:.2f}, {r.T[1]:.2f}, {r.T[2]:.2f}] mm, "
          f"rotation {rotation_angle_deg(r.R):.3f} deg")
    if cal.outliers:
        print(f"outlier views (error > 3x median and > 1 px): {', '.join(cal.outliers)} — check them "
              "(blur, a moved board) or rerun with --drop-outliers")


# ----------------------------------------------------------------------------- hand-eye


def run_hand_eye(args: argparse.Namespace) -> int:
    rig = load_rig(args.rig)
    board = _board(args)
    if board.is_symmetric:
        raise InputError(f"--board {args.board}: a chessboard with cols + rows even looks the same turned "
                         "by 180 degrees, so its pose is ambiguous between views; use a board with one odd "
                         "and one even corner count, or --charuco")
    T_bf, T_lb, used = [], [], []
    for name, T, dl, _ in _posed_views(args, rig, lambda img: detect_board(img, board), want_right=False):
        if dl is None:
            print(f"  {name}: skipped, board not found in the left image")
            continue
        T_cam, rms = board_pose(dl, board, rig.left)
        print(f"  {name}: board at {np.linalg.norm(T_cam[:3, 3]):.0f} mm, PnP {rms:.3f} px ({len(dl)} corners)")
        T_bf.append(T)
        T_lb.append(T_cam)
        used.append(name)
    if len(used) < MIN_HAND_EYE_VIEWS:
        raise InputError(f"only {len(used)} views with the board found and a pose, need at least {MIN_HAND_EYE_VIEWS}")
    res = calibrate_hand_eye(T_bf, T_lb, args.method)
    if res.max_rotation_deg < MIN_ROTATION_DEG and not args.force:
        raise InputError(f"{res.warnings[0]} (nothing written; --force writes it anyway)")
    for w in res.warnings:
        print(f"photoservo calibrate: warning: {w}", file=sys.stderr)
    rv = np.degrees(cv2.Rodrigues(res.R)[0].ravel())
    print(f"hand-eye ({args.method}, {len(used)} views, rotation between poses up to {res.max_rotation_deg:.1f} deg):")
    print(f"  X_flange = R X_left + t:  t = [{res.t[0]:.2f}, {res.t[1]:.2f}, {res.t[2]:.2f}] mm, "
          f"R = rotation vector [{rv[0]:.3f}, {rv[1]:.3f}, {rv[2]:.3f}] deg")
    print(f"  residual: board position spread {res.position_residual_mm:.2f} mm RMS, "
          f"orientation spread {res.rotation_residual_deg:.3f} deg RMS")
    out = Path(args.out or args.rig)
    save_rig(Rig(rig.left, rig.right, rig.R, rig.T, hand_eye=(res.R, res.t)), out)
    print(f"wrote [hand_eye] to {out}")
    return 0


# ----------------------------------------------------------------------------- water


def set_toml_key(text: str, dotted: str, value: float) -> str:
    """`text` with `[section] key = value` set, keeping every other line and the key's
    trailing comment; the table or key is added when missing."""
    section, _, key = dotted.rpartition(".")
    if not section or not key:
        raise InputError(f"--key '{dotted}': expected SECTION.KEY")
    lines = text.splitlines()
    new = f"{key} = {value:.2f}"
    header = re.compile(r"^\s*\[\s*" + re.escape(section) + r"\s*\]\s*(#.*)?$")
    start = next((i for i, ln in enumerate(lines) if header.match(ln)), None)
    if start is None:
        lines += ["", f"[{section}]", f"{new}  # set by photoservo calibrate water"]
    else:
        end = next((i for i in range(start + 1, len(lines)) if re.match(r"^\s*\[", lines[i])), len(lines))
        kv = re.compile(r"^(\s*)" + re.escape(key) + r"\s*=\s*[^#]*?(\s*#.*)?$")
        for i in range(start + 1, end):
            m = kv.match(lines[i])
            if m:
                lines[i] = f"{m.group(1)}{new}{m.group(2) or ''}"
                break
        else:
            lines.insert(start + 1, f"{new}  # set by photoservo calibrate water")
    out = "\n".join(lines) + "\n"
    try:
        tomllib.loads(out)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"cannot set '{dotted}': the result is not valid TOML ({e})") from None
    return out


def _water_target(args: argparse.Namespace, rig: Rig
                  ) -> tuple[Callable[[np.ndarray], Any], Callable[[Any, Any], tuple[np.ndarray, str]]]:
    """(detect(image) -> detection or None, locate(left, right) -> (points in the left camera
    frame (n, 3) mm, how)) for a floating board or for single markers (--markers)."""
    if args.markers is not None:
        side = args.markers
        if not side > 0:
            raise InputError(f"--markers must be the marker side in mm (> 0), got {side}")
        if not hasattr(cv2.aruco, args.dict):
            raise InputError(f"--dict: unknown ArUco dictionary '{args.dict}'")

        def locate_markers(dl: dict, dr: dict | None) -> tuple[np.ndarray, str]:
            P, n_tri, n_pnp = marker_points_left(dl, dr, side, rig)
            return P, f"{n_tri} markers triangulated, {n_pnp} by PnP"

        return (lambda img: detect_markers(img, args.dict) or None), locate_markers
    if not args.board or args.square_mm is None:
        raise InputError("give the floating target: --board COLSxROWS --square-mm S, or --markers SIDE_MM")
    board = _board(args)

    def locate_board(dl: BoardDetection, dr: BoardDetection | None) -> tuple[np.ndarray, str]:
        both = dr is not None and len(np.intersect1d(dl.ids, dr.ids)) >= MIN_COMMON_CORNERS
        return board_points_left(dl, dr, board, rig), "triangulated" if both else "PnP"

    return (lambda img: detect_board(img, board)), locate_board


def run_water(args: argparse.Namespace) -> int:
    rig = load_rig(args.rig)
    if rig.hand_eye is None:
        raise InputError(f"{args.rig}: no [hand_eye] table; run `photoservo calibrate hand-eye` first")
    T_flange_left = rig.T_flange_left()
    if args.live == bool(args.views):
        raise InputError("give either --views DIR (saved views) or --live (cameras and arm now)")
    detect, locate = _water_target(args, rig)
    views = _live_views(args, rig, detect) if args.live else _posed_views(args, rig, detect, want_right=True)
    points = []
    for name, T_bf, dl, dr in views:
        if dl is None:
            print(f"  {name}: skipped, nothing found in the left image")
            continue
        P, how = locate(dl, dr)
        T_base_left = T_bf @ T_flange_left
        P_base = P @ T_base_left[:3, :3].T + T_base_left[:3, 3]
        print(f"  {name}: {len(P)} corners ({how}), mean z {P_base[:, 2].mean():.1f} mm")
        points.append(P_base)
    if not points:
        raise InputError(f"--views {args.views}: the board or markers were not found in any view")
    plane = fit_water_plane(np.vstack(points))
    n = plane.normal
    print(f"water plane (base frame): z = {plane.z_mm:.1f} mm at ({plane.centroid[0]:.0f}, {plane.centroid[1]:.0f}); "
          f"normal [{n[0]:.4f}, {n[1]:.4f}, {n[2]:.4f}], tilt {plane.tilt_deg:.2f} deg; "
          f"{plane.n_points} points, {plane.rms_mm:.2f} mm RMS off the plane")
    if plane.tilt_deg > 3.0 and len(points) > 1:
        print(f"photoservo calibrate: warning: the plane is tilted {plane.tilt_deg:.1f} deg: waves, or a base "
              "frame that is not level", file=sys.stderr)
    print(f"water_z_mm = {plane.z_mm:.1f}")
    if args.update:
        p = Path(args.update)
        try:
            text = p.read_text() if p.exists() else ""
        except OSError as e:
            raise InputError(f"{p}: cannot read ({e.strerror or e})") from None
        write_text_atomic(p, set_toml_key(text, args.key, plane.z_mm))
        print(f"set {args.key} = {plane.z_mm:.2f} in {p}")
        section, _, key = args.key.rpartition(".")
        if key not in read_toml(configs_dir() / "default.toml").get(section, {}):
            print(f"note: '{args.key}' is not a key of configs/default.toml: `--config {p}` will reject it "
                  "until the tracker's config has it (use --key to pick another)")
    return 0


# ----------------------------------------------------------------------------- capture


class _EnterKey:
    """Counts Enter presses on stdin from a daemon thread; 'q' (or end of input) sets `quit`."""

    def __init__(self) -> None:
        self.presses = 0
        self.quit = False
        self._lock = threading.Lock()
        threading.Thread(target=self._run, daemon=True, name="enter-key").start()

    def _run(self) -> None:
        try:
            for line in sys.stdin:
                with self._lock:
                    if line.strip().lower() == "q":
                        self.quit = True
                        return
                    self.presses += 1
        except (OSError, ValueError):  # no usable terminal: behave as end of input
            pass
        self.quit = True

    def take(self) -> bool:
        with self._lock:
            if self.presses:
                self.presses -= 1
                return True
            return False


def run_capture(args: argparse.Namespace) -> int:
    from photoservo.record.recorder import Recorder

    if args.interval < 0 or args.count < 0:
        raise InputError("--interval and --count must be >= 0")
    board = Board.parse(args.board, args.square_mm, args.charuco, args.marker_mm, args.dict) if args.board else None
    if args.require_board and board is None:
        raise InputError("--require-board needs --board")
    out = Path(args.out)
    config = load_config(args.config, args.overrides)
    source = make_source(_cameras(args, config.cameras))
    link = None
    if args.port:
        from photoservo.robot.pa10 import fk

        link = Link(args.port, config.link)
    rows, poses = _existing_rows(out / "capture.csv"), _existing_rows(out / "poses.csv")
    first = 1 + max((int(r[0]) for r in rows if r[0].isdigit()), default=-1)  # continue a session
    saved = 0
    enter = None if args.interval > 0 else _EnterKey()
    if enter is not None:
        print("press Enter to save a pair, q + Enter to finish")
    rec = Recorder.open(args.save, "calibrate", mode="lossless", view=args.spawn, connect_url=args.connect)
    try:
        if link is not None:
            try:
                link.open()
            except LinkError as e:
                raise InputError(f"--port {args.port}: {e}") from None
        with source:
            for w in source.warnings:
                print(f"photoservo calibrate: warning: {w}", file=sys.stderr)
            t_next = time.monotonic()
            for frame in source:
                dl = detect_board(frame.left, board) if board else None
                dr = detect_board(frame.right, board) if board else None
                if board is not None:
                    rec.log_frame(frame.index, frame.t, draw_detection(frame.left, dl, board),
                                  draw_detection(frame.right, dr, board), capture_times=(frame.t_left, frame.t_right))
                else:
                    rec.log_frame(frame.index, frame.t, frame.left, frame.right,
                                  capture_times=(frame.t_left, frame.t_right))
                if enter is not None:
                    due = enter.take()
                    if not due and enter.quit:
                        break
                else:
                    due = frame.t >= t_next
                if not due:
                    continue
                if args.require_board and (dl is None or dr is None):
                    print(f"  pair {frame.index}: board not in both images, not saved")
                    continue
                name = f"{first + saved:04d}"
                row = [name, f"{frame.t_left:.6f}", f"{frame.t_right:.6f}"]
                if link is not None:
                    try:
                        q = link.state_at(frame.t).q
                    except LinkError as e:
                        raise InputError(f"--port {args.port}: {e}") from None
                    except LookupError as e:
                        print(f"  pair {frame.index}: no flange pose at its capture time ({e}), not saved")
                        continue
                    poses.append([name, *pose_row(fk(q)), *(f"{x:.6f}" for x in q)])
                write_image_atomic(out / "left" / f"{name}.png", frame.left)
                write_image_atomic(out / "right" / f"{name}.png", frame.right)
                rows.append(row)
                saved += 1
                seen = "" if board is None else f", board {'found' if dl else 'NOT found'} left, " \
                                                  f"{'found' if dr else 'NOT found'} right"
                print(f"  saved {name} (skew {1e3 * frame.skew_s:.1f} ms{seen})")
                t_next = frame.t + args.interval
                if args.count and saved >= args.count:
                    break
            stats = source.stats.summary()
    finally:
        rec.close()
        if link is not None:
            link.close()
        if rows:
            write_text_atomic(out / "capture.csv", "name,t_left,t_right\n" + "".join(",".join(r) + "\n" for r in rows))
        if poses:
            header = ",".join(("name", *POSE_COLUMNS, *JOINT_COLUMNS))
            write_text_atomic(out / "poses.csv", header + "\n" + "".join(",".join(r) + "\n" for r in poses))
    print(f"saved {saved} pairs to {out} ({stats}); preview recording {rec.path}")
    return 0


def _existing_rows(path: Path) -> list[list[str]]:
    """Data rows of a CSV that an earlier capture into the same folder wrote (kept, appended to)."""
    if not path.is_file():
        return []
    return [r for r in csv.reader(path.read_text().splitlines()[1:]) if r]


__all__ = ["add_arguments", "pose_row", "read_flange_poses", "run", "set_toml_key"]
