"""photoservo calibrate capture: synchronised stereo pairs (and flange poses) for calibration."""

from __future__ import annotations

import argparse
import logging
import csv
import sys
import threading
import time
from pathlib import Path

from photoservo.cli.calibrate.common import cameras_config
from photoservo.cli.calibrate.poses import JOINT_COLUMNS, POSE_COLUMNS, pose_row
from photoservo.cli.options import check_display, open_link
from photoservo.config import load_config
from photoservo.errors import InputError
from photoservo.fileio import write_image_atomic, write_text_atomic
from photoservo.vision.board import Board, detect_board, draw_detection
from photoservo.vision.sources import make_source

log = logging.getLogger(__name__)


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

    board = Board.parse(args.board, args.square_mm, args.charuco, args.marker_mm, args.dict) if args.board else None
    if args.require_board and board is None:
        raise InputError("--require-board needs --board")
    out = Path(args.out)
    config = load_config(args.config, args.overrides)
    source = make_source(cameras_config(args, config.cameras))
    if args.spawn:
        check_display("--spawn")
    link = open_link(args.port, config.link) if args.port else None
    rows, poses = _existing_rows(out / "capture.csv"), _existing_rows(out / "poses.csv")
    first = 1 + max((int(r[0]) for r in rows if r[0].isdigit()), default=-1)  # continue a session
    saved = 0
    enter = None if args.interval > 0 else _EnterKey()
    if enter is not None:
        print("press Enter to save a pair, q + Enter to finish")
    with source:  # opens, or fails here: a failed start leaves no recording
        pass
    rec = Recorder.open(args.save, "calibrate", mode="full", view=args.spawn, connect_url=args.connect)
    try:
        with source:
            for w in source.warnings:
                log.warning(w)
            t_next = time.monotonic()
            for frame in source:
                dl, dr = _preview(rec, frame, board)
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
                if not _save_pair(out, name, frame, link, rows, poses):
                    continue
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
        _write_csvs(out, rows, poses)
    print(f"saved {saved} pairs to {out} ({stats}); preview recording {rec.path}")
    return 0


def _save_pair(out: Path, name: str, frame, link, rows: list[list[str]], poses: list[list[str]]) -> bool:
    """Write a pair's images and its rows (capture times; with a link, the flange pose at the
    capture time). False, nothing written, when the arm's state at that time is not known."""
    if link is not None:
        from photoservo.robot.pa10 import fk

        try:
            q = link.state_at(frame.t).q
        except LookupError as e:
            print(f"  pair {frame.index}: no flange pose at its capture time ({e}), not saved")
            return False
        poses.append([name, *pose_row(fk(q)), *(f"{x:.6f}" for x in q)])
    write_image_atomic(out / "left" / f"{name}.png", frame.left)
    write_image_atomic(out / "right" / f"{name}.png", frame.right)
    rows.append([name, f"{frame.t_left:.6f}", f"{frame.t_right:.6f}"])
    return True


def _preview(rec, frame, board: Board | None) -> tuple:
    """Log a pair to the preview recording, with the found corners drawn when a board is given;
    return the (left, right) detections (None without a board or when not found)."""
    times = (frame.t_left, frame.t_right)
    if board is None:
        rec.log_frame(frame.index, frame.t, frame.left, frame.right, capture_times=times)
        return None, None
    dl, dr = detect_board(frame.left, board), detect_board(frame.right, board)
    rec.log_frame(frame.index, frame.t, draw_detection(frame.left, dl, board), draw_detection(frame.right, dr, board),
                  capture_times=times)
    return dl, dr


def _write_csvs(out: Path, rows: list[list[str]], poses: list[list[str]]) -> None:
    """capture.csv (name and capture times) and, with --port, poses.csv (the poses CSV format)."""
    if rows:
        write_text_atomic(out / "capture.csv", "name,t_left,t_right\n" + "".join(",".join(r) + "\n" for r in rows))
    if poses:
        header = ",".join(("name", *POSE_COLUMNS, *JOINT_COLUMNS))
        write_text_atomic(out / "poses.csv", header + "\n" + "".join(",".join(r) + "\n" for r in poses))


def _existing_rows(path: Path) -> list[list[str]]:
    """Data rows of a CSV that an earlier capture into the same folder wrote (kept, appended to)."""
    if not path.is_file():
        return []
    return [r for r in csv.reader(path.read_text().splitlines()[1:]) if r]
