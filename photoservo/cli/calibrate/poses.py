"""Flange poses CSV of hand-eye and water calibration (written by `calibrate capture --port`): a
header row, then one row per view; `name` is the image file name with or without its extension.
Either
    name,x_mm,y_mm,z_mm,rx_rad,ry_rad,rz_rad   T_base_flange: position (mm) and rotation vector
                                               (axis x angle, rad) of the flange in the base frame
or  name,q1_rad,...,q7_rad                     PA-10 joint angles, converted with pa10.fk
(when both are present the pose columns are used)."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.vision.calibrate import make_T


POSE_COLUMNS = ("x_mm", "y_mm", "z_mm", "rx_rad", "ry_rad", "rz_rad")
JOINT_COLUMNS = tuple(f"q{i}_rad" for i in range(1, 8))


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
