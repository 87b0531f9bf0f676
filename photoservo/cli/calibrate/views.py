"""Calibration views: images from folders (paired by name, with their flange poses) or live
from the cameras and the arm."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from photoservo.cli.calibrate.common import cameras_config
from photoservo.cli.calibrate.poses import read_flange_poses
from photoservo.config import load_config
from photoservo.errors import InputError
from photoservo.fileio import read_image
from photoservo.robot.link import Link, LinkError
from photoservo.vision.rig import Rig
from photoservo.vision.sources import IMAGE_SUFFIXES, StereoSource, make_source


LIVE_TIMEOUT_S = 30.0  # water --live gives up when the board is not seen for this long


def image_files(folder: Path, what: str) -> dict[str, Path]:
    """Images in a folder by file name (sorted)."""
    if not folder.is_dir():
        raise InputError(f"{what} {folder}: folder not found")
    files = {p.name: p for p in sorted(folder.iterdir()) if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES}
    if not files:
        raise InputError(f"{what} {folder}: no images (.png, .jpg, ...) in the folder")
    return files


def read_sized(path: Path, size: tuple[int, int] | None, what: str) -> np.ndarray:
    img = read_image(path, what)
    if size is not None and (img.shape[1], img.shape[0]) != tuple(size):
        raise InputError(f"{path}: image is {img.shape[1]}x{img.shape[0]}, expected {size[0]}x{size[1]} ({what})")
    return img


def _views_dir(views: Path, side: str) -> Path | None:
    """DIR/left (or DIR/right); for the left side, DIR itself when it has no left/ subfolder."""
    if (views / side).is_dir():
        return views / side
    return views if side == "left" and views.is_dir() else None


def posed_views(args: argparse.Namespace, rig: Rig, detect: Callable[[np.ndarray], Any], want_right: bool
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
        dl = detect(read_sized(left[name], rig.left.size, "left image"))
        dr = detect(read_sized(right[name], rig.right.size, "right image")) if name in right else None
        out.append((name, T, dl, dr))
    return out


def live_views(args: argparse.Namespace, rig: Rig, detect: Callable[[np.ndarray], Any]
                ) -> list[tuple[str, np.ndarray, Any, Any]]:
    """`--frames` pairs with the board in the left image, each with the flange pose at its
    capture time from the arm's link (forward kinematics of the interpolated joint state)."""
    from photoservo.robot.pa10 import fk

    if not args.port:
        raise InputError("--live needs --port (the arm's bridge) for the flange pose")
    if args.frames < 1:
        raise InputError(f"--frames must be >= 1, got {args.frames}")
    config = load_config(args.config, args.overrides)
    source = make_source(cameras_config(args, config.cameras))
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
