"""photoservo calibrate water: the water surface height in the base frame; --update writes it
into a config file."""

from __future__ import annotations

import argparse
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import tomlkit

from photoservo.cli.calibrate.common import board_of
from photoservo.cli.calibrate.views import live_views, posed_views
from photoservo.errors import InputError
from photoservo.fileio import write_text_atomic
from photoservo.tomlconf import configs_dir, read_toml
from photoservo.vision.board import BoardDetection, detect_board, detect_markers
from photoservo.vision.calibrate import MIN_COMMON_CORNERS, board_points_left, fit_water_plane, marker_points_left
from photoservo.vision.rig import Rig, load_rig

log = logging.getLogger(__name__)


def set_toml_key(text: str, dotted: str, value: float) -> str:
    """`text` (a user's TOML file) with `[section] key = value` set by tomlkit, keeping every
    other line, comment and the layout; the table or key is added when missing."""
    section, _, key = dotted.rpartition(".")
    if not section or not key or "." in section:
        raise InputError(f"--key '{dotted}': expected SECTION.KEY")
    try:
        doc = tomlkit.parse(text)
    except tomlkit.exceptions.ParseError as e:
        raise InputError(f"cannot set '{dotted}': the file is not valid TOML ({e})") from None
    table = doc.get(section)
    if table is None:
        table = tomlkit.table()
        doc[section] = table
    elif not isinstance(table, dict):
        raise InputError(f"cannot set '{dotted}': '{section}' is not a table in the file")
    if key in table:
        table[key] = round(value, 2)  # tomlkit keeps the key's trailing comment
    else:
        table.add(key, round(value, 2))
        table[key].comment("set by photoservo calibrate water")
    return tomlkit.dumps(doc)


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
    board = board_of(args)

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
    views = live_views(args, rig, detect) if args.live else posed_views(args, rig, detect, want_right=True)
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
        log.warning(f"the plane is tilted {plane.tilt_deg:.1f} deg: waves, or a base "
              "frame that is not level")
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
