"""photoservo calibrate board: a printable board image."""

from __future__ import annotations

import argparse

from photoservo.cli.calibrate.common import board_of
from photoservo.errors import InputError
from photoservo.fileio import write_image_atomic
from photoservo.vision.board import board_texture


def run_board(args: argparse.Namespace) -> int:
    board = board_of(args)
    if not args.dpi > 0:
        raise InputError(f"--dpi must be > 0, got {args.dpi}")
    img, _ = board_texture(board, args.dpi / 25.4)
    write_image_atomic(args.out, img)
    w, h = img.shape[1] * 25.4 / args.dpi, img.shape[0] * 25.4 / args.dpi
    print(f"wrote {args.out}: {board.cols}x{board.rows} inner corners, {board.square_mm} mm squares"
          f"{' (ChArUco ' + board.dictionary + ')' if board.charuco else ''}; print at {args.dpi:g} dpi, "
          f"no scaling: {w:.0f} x {h:.0f} mm. Measure a square after printing and pass that as --square-mm.")
    return 0
