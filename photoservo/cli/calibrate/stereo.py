"""photoservo calibrate stereo: both cameras and the stereo extrinsics from board pairs."""

from __future__ import annotations

import argparse
from pathlib import Path

from photoservo.cli.calibrate.common import board_of
from photoservo.cli.calibrate.views import image_files, read_sized
from photoservo.errors import InputError
from photoservo.vision.board import detect_board
from photoservo.vision.calibrate import calibrate_stereo, pair_detections, rotation_angle_deg
from photoservo.vision.rig import save_rig


def run_stereo(args: argparse.Namespace) -> int:
    board = board_of(args)
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
        il = read_sized(left[n], size_l, "left image")
        ir = read_sized(right[n], size_r, "right image")
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
