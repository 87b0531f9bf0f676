"""photoservo calibrate hand-eye: the left camera's pose on the flange into the rig's [hand_eye]."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import cv2
import numpy as np

from photoservo.cli.calibrate.common import board_of
from photoservo.cli.calibrate.views import posed_views
from photoservo.errors import InputError
from photoservo.vision.board import detect_board
from photoservo.vision.calibrate import MIN_HAND_EYE_VIEWS, MIN_ROTATION_DEG, board_pose, calibrate_hand_eye
from photoservo.vision.rig import Rig, load_rig, save_rig

log = logging.getLogger(__name__)


def run_hand_eye(args: argparse.Namespace) -> int:
    rig = load_rig(args.rig)
    board = board_of(args)
    if board.is_symmetric:
        raise InputError(f"--board {args.board}: a chessboard with cols + rows even looks the same turned "
                         "by 180 degrees, so its pose is ambiguous between views; use a board with one odd "
                         "and one even corner count, or --charuco")
    T_bf, T_lb, used = [], [], []
    for name, T, dl, _ in posed_views(args, rig, lambda img: detect_board(img, board), want_right=False):
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
        log.warning(w)
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
