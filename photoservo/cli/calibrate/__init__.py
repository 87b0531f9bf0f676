"""photoservo calibrate — the stereo rig, the hand-eye transform and the water plane.

Examples (in the order of a calibration; `photoservo calibrate ACTION --help` for each):
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

One module per action (board, stereo, hand_eye, water, capture); shared options in common.py,
views and poses files in views.py and poses.py.
"""

from __future__ import annotations

import argparse

from photoservo.cli.calibrate.board import run_board
from photoservo.cli.calibrate.capture import run_capture
from photoservo.cli.calibrate.common import BOARD_HELP, board_options, source_options
from photoservo.cli.calibrate.hand_eye import run_hand_eye
from photoservo.cli.calibrate.stereo import run_stereo
from photoservo.cli.calibrate.water import run_water
from photoservo.cli.options import add_config_options, bounded
from photoservo.vision.calibrate import MIN_ROTATION_DEG


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    _board_parser(sub)
    _stereo_parser(sub)
    _hand_eye_parser(sub)
    _water_parser(sub)
    _capture_parser(sub)


def _board_parser(sub) -> None:
    b = sub.add_parser("board", help="write a printable board image",
                       description="Write a printable calibration board (PNG) at a given resolution.")
    board_options(b)
    b.add_argument("--out", required=True, metavar="BOARD.png", help="image file to write (.png)")
    b.add_argument("--dpi", type=bounded(float, 10.0, 2400.0), default=300.0, help="print resolution (default 300)")


def _stereo_parser(sub) -> None:
    s = sub.add_parser("stereo", help="calibrate both cameras and the stereo extrinsics",
                       description="Calibrate the stereo rig from image pairs of a board (paired by file "
                                   "name). " + BOARD_HELP + ".")
    s.add_argument("--left", required=True, metavar="DIR", help="left camera images")
    s.add_argument("--right", required=True, metavar="DIR", help="right camera images (same file names)")
    board_options(s)
    s.add_argument("--out", default="rig.toml", metavar="RIG.toml", help="rig file to write (default rig.toml)")
    s.add_argument("--free-k3", action="store_true", help="also fit k3 (wide-angle lenses; needs many views)")
    s.add_argument("--drop-outliers", action="store_true", help="calibrate again without the outlier views")


def _hand_eye_parser(sub) -> None:
    h = sub.add_parser("hand-eye", help="the left camera's pose on the flange",
                       description="Eye-in-hand calibration: a board fixed in the world, seen by the left "
                                   "camera from several flange poses -> the rig's [hand_eye]. Pose CSV "
                                   "columns: name,x_mm,y_mm,z_mm,rx_rad,ry_rad,rz_rad (T_base_flange, "
                                   "rotation vector) or name,q1_rad..q7_rad (PA-10 joints).")
    _rig_views_poses(h, "the stereo rig from `calibrate stereo`", True, "left images (DIR or DIR/left)")
    board_options(h)
    h.add_argument("--method", default="park", choices=["park", "tsai", "horaud", "andreff", "daniilidis"],
                   help="cv2.calibrateHandEye method (default park: as accurate as tsai on the test views, "
                        "and tsai gives up on motions that rotate less than ~15 deg)")
    h.add_argument("--out", metavar="RIG.toml", help="rig file to write (default: update --rig)")
    h.add_argument("--force", action="store_true",
                   help=f"write the result even when the poses rotate less than {MIN_ROTATION_DEG:.0f} deg")


def _rig_views_poses(p, rig_help: str, views_required: bool, views_help: str) -> None:
    """--rig, --views and --poses: a rig and board views taken from known flange poses."""
    p.add_argument("--rig", required=True, metavar="RIG.toml", help=rig_help)
    p.add_argument("--views", required=views_required, metavar="DIR", help=views_help)
    p.add_argument("--poses", metavar="POSES.csv", help="flange poses (default DIR/poses.csv)")


def _water_parser(sub) -> None:
    w = sub.add_parser("water", help="the water surface height in the base frame",
                       description="Fit the water plane to a board or single ArUco markers (--markers) "
                                   "floating on it, seen by the calibrated rig (with [hand_eye]) from known "
                                   "flange poses. One view of one board or of three markers is enough; "
                                   "markers spread out give the tilt too.")
    _rig_views_poses(w, "the rig, with [hand_eye] (`calibrate hand-eye`)", False,
                     "DIR/left (+ DIR/right) images, or DIR")
    w.add_argument("--markers", type=bounded(float, 0.0, 1000.0, lo_open=True, unit="mm"), metavar="SIDE_MM",
                   help="single ArUco markers of this side (mm, black square) from --dict instead of a board")
    w.add_argument("--live", action="store_true",
                   help="measure now: read pairs from the cameras ([cameras] or the source flags) and the "
                        "flange pose from the arm (--port) instead of --views")
    w.add_argument("--frames", type=bounded(int, 1, 1000), default=5, metavar="N",
                   help="--live: pairs with the board found to use (default 5; gives up after 30 s)")
    w.add_argument("--port", help="--live: serial port of the arm's bridge")
    source_options(w)
    add_config_options(w)
    board_options(w, required=False)
    w.add_argument("--update", metavar="CFG.toml", help="write the height into this config file")
    w.add_argument("--key", default="tracker.water_z_mm", metavar="SECTION.KEY",
                   help="config key for --update (default tracker.water_z_mm)")


def _capture_parser(sub) -> None:
    c = sub.add_parser("capture", help="save synchronised pairs (and flange poses) for calibration",
                       description="Save stereo pairs from cameras, videos or folders, at an interval or "
                                   "on Enter ('q' + Enter ends), with a live preview in Rerun (corners "
                                   "drawn when --board is given). With --port, the flange pose at each "
                                   "pair's capture time goes to OUT/poses.csv.")
    source_options(c)
    c.add_argument("--out", required=True, metavar="DIR", help="writes DIR/left, DIR/right, DIR/capture.csv")
    c.add_argument("--interval", type=bounded(float, 0.0, 3600.0, unit="s"), default=0.0, metavar="S", help="save every S seconds (0: on Enter)")
    c.add_argument("--count", type=bounded(int, 0, 100000), default=0, metavar="N", help="stop after N pairs (0: until q / end)")
    board_options(c, required=False)   # the preview draws the board's corners it finds
    c.set_defaults(square_mm=25.0)
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
