"""Options shared by the calibrate actions: the board and the stereo source."""

from __future__ import annotations

import argparse
import dataclasses

from photoservo.cli.options import bounded
from photoservo.errors import InputError
from photoservo.vision.board import Board, DEFAULT_DICTIONARY
from photoservo.vision.source_config import CamerasParams, SourceConfig, source_config


BOARD_HELP = "board size as COLSxROWS INNER corners (where four squares meet): 10 x 7 squares -> 9x6"


# ----------------------------------------------------------------------------- arguments


def board_options(p: argparse.ArgumentParser, required: bool = True) -> None:
    p.add_argument("--board", required=required, metavar="COLSxROWS", help=BOARD_HELP)
    p.add_argument("--square-mm", type=bounded(float, 0.0, 1000.0, lo_open=True, unit="mm"), required=required, metavar="S", help="square side (mm), as printed")
    p.add_argument("--charuco", action="store_true", help="a ChArUco board (markers in the white squares)")
    p.add_argument("--marker-mm", type=bounded(float, 0.0, 1000.0, unit="mm"), default=0.0, metavar="M",
                   help="ChArUco marker side (mm); default 0.7 x square")
    p.add_argument("--dict", default=DEFAULT_DICTIONARY, metavar="NAME",
                   help=f"ChArUco ArUco dictionary (default {DEFAULT_DICTIONARY}; also finds DICT_4X4_50/100 boards)")


def source_options(p: argparse.ArgumentParser) -> None:
    """Stereo source flags; each overrides its key of the config's [cameras] section."""
    src = p.add_mutually_exclusive_group()
    src.add_argument("--devices", nargs=2, metavar=("LEFT", "RIGHT"), help="two OpenCV devices: index or path")
    src.add_argument("--side-by-side", metavar="DEVICE", help="one device with left|right halves")
    src.add_argument("--videos", nargs=2, metavar=("LEFT", "RIGHT"), help="two video files")
    src.add_argument("--folders", nargs=2, metavar=("LEFT", "RIGHT"), help="two image folders")
    p.add_argument("--width", type=bounded(int, 0, 16384), help="capture width (px per camera; 0 = device default)")
    p.add_argument("--height", type=bounded(int, 0, 16384), help="capture height (px; 0 = device default)")
    p.add_argument("--fps", type=bounded(float, 0.0, 1000.0), help="requested frame rate (0 = device default)")
    p.add_argument("--fourcc", help="pixel format, e.g. MJPG (default: the device's)")
    p.add_argument("--exposure", type=bounded(float, 0.0, 1e6), help="lock exposure (device units; 0 = automatic)")
    p.add_argument("--white-balance-k", type=bounded(float, 0.0, 15000.0),
                   help="lock white balance (K; 0 = automatic)")
    p.add_argument("--max-skew-ms", type=bounded(float, 0.0, 10000.0),
                   help="drop pairs whose left/right capture times differ more (ms)")


def cameras_config(args: argparse.Namespace, cams: CamerasParams) -> SourceConfig:
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


def board_of(args: argparse.Namespace) -> Board:
    return Board.parse(args.board, args.square_mm, args.charuco, args.marker_mm, args.dict)
