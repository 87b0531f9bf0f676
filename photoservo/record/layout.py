"""What a photoservo recording holds and where (issues 6 and 13): the entity tree, the packed
per-frame numbers, and the viewer layout. The recorder writes and the reader reads by these
names only.

Entity tree (mm; `world` is the PA-10 base frame, z up)::

    world                      ViewCoordinates RIGHT_HAND_Z_UP (static)
    world/arm/link0..7         Transform3D T_base_link_i from forward kinematics + axes
    world/arm/skeleton         LineStrips3D through the link origins
    world/rig                  Transform3D T_base_left (the left camera; per frame, when known)
    world/rig/left             Pinhole K, camera_xyz RDF (X right, Y down, Z forward) (static)
    world/rig/left/video       VideoStream: the watch-only camera video (compact, preview)
    world/rig/left/image       Image: the full frame, raw pixels (full mode)
    world/rig/left/model/inner Points2D: the best model's projected inner points (green; and
    world/rig/left/model/outer the outer ones, magenta), at most drawing.DRAW_POINTS each
    world/rig/right            Transform3D X_right = R X_left + T (static) + Pinhole; as left
    world/target/estimate      Transform3D T_base_model + axes + Boxes3D (size_mm, flat)
    world/target/truth         the same for the simulator's ground truth
    world/target/desired       Transform3D T_base_cam_desired + axes
    world/flange/path          LineStrips3D, the flange's last PATH_S seconds
    plots/fitness|alpha|found  Scalars
    timing/<stage>_ms          Scalars (ms)
    arm/q_deg                  Scalars, 7 named series (S1..W2): joint angles in DEGREES
    arm/setpoint_deg           the motion setpoint's angles (deg)
    arm/command_deg_s          the velocity command sent (deg/s)
    events                     TextLog
    data/planes                AnyValues `planes`: the tracker's input, lossless (compact mode;
                               `record.planes`), one blob per stereo frame
    data/frame|estimate|truth  AnyValues `values`: the exact float64 numbers replay reads
                               back, one vector per row laid out by FRAME/EST/TRUTH_LAYOUT
    setup/run                  TextDocument JSON: verb, mode, replayable, seed, versions, ...
    setup/rig|config           TextDocument: the rig TOML, the effective config TOML
    setup/photo_model          AnyValues npz: the PhotoModel arrays, bit-exact
    setup/photo_model/photo    the photo (PNG) with the inner/outer points on it
    setup/WARNING              (preview mode only) "cannot be replayed"

Timelines: `frame` (sequence: the loop's frame index) and `time` (duration, seconds on the
loop's monotonic clock). Arm and event logs carry `time` only.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from photoservo.robot.pa10 import JOINT_NAMES  # noqa: F401 - the series' names, re-exported


class _LazyModule:
    """A module imported on first attribute access. `import rerun` takes 1-2 s here, and
    config.py imports `record.recorder` for `RecordingParams`, which every verb loads."""

    def __init__(self, name: str) -> None:
        self._name = name

    def __getattr__(self, attr: str) -> Any:
        value = getattr(importlib.import_module(self._name), attr)
        setattr(self, attr, value)   # later look-ups are plain attribute hits
        return value


rr: Any = _LazyModule("rerun")
rrb: Any = _LazyModule("rerun.blueprint")

APPLICATION_ID = "photoservo"
#: 1: issue 6 (frames as images, segments, arm in rad); 2: issue 13 (modes compact/full/preview,
#: one file, arm in degrees). The reader reads both.
FORMAT_VERSION = 2
SIDES = ("left", "right")

E_RUN, E_RIG_TOML, E_CONFIG, E_WARNING = "setup/run", "setup/rig", "setup/config", "setup/WARNING"
E_MODEL, E_PHOTO = "setup/photo_model", "setup/photo_model/photo"
E_CAM = {"left": "world/rig/left", "right": "world/rig/right"}
E_IMAGE = {s: f"{p}/image" for s, p in E_CAM.items()}
E_VIDEO = {s: f"{p}/video" for s, p in E_CAM.items()}
E_POINTS = {s: f"{p}/model" for s, p in E_CAM.items()}
E_PLANES = "data/planes"
E_DATA_FRAME, E_DATA_EST, E_DATA_TRUTH = "data/frame", "data/estimate", "data/truth"
E_EVENTS = "events"
#: arm series: entity -> (key in `reader.Recording.arm`, factor from the recorded unit to rad)
E_ARM = {"arm/q_deg": ("q", math.pi / 180), "arm/setpoint_deg": ("setpoint", math.pi / 180),
         "arm/command_deg_s": ("command", math.pi / 180)}
E_ARM_V1 = {"arm/q": ("q", 1.0), "arm/setpoint": ("setpoint", 1.0), "arm/command": ("command", 1.0)}

#: Per-frame numbers replay reads back exactly, one float64 vector per row (NaN = absent):
#: one AnyValues component instead of one per field (each costs ~0.2 ms of Python in rerun).
FRAME_LAYOUT = (("capture_times", 2), ("T_base_left", 16))
EST_LAYOUT = (("found", 1), ("fitness", 1), ("generations", 1), ("alpha", 1), ("rotation", 9),
              ("position_mm", 3), ("size_mm", 2), ("T_base_left", 16))
TRUTH_LAYOUT = (("T_base_target", 16), ("size_mm", 2))
Layout = tuple[tuple[str, int], ...]


def pack(layout: Layout, values: Mapping[str, Any]) -> np.ndarray:
    """`values` laid out in one float64 vector by `layout` ((name, length), ...); a missing
    or None value becomes NaNs."""
    parts = []
    for name, n in layout:
        v = values.get(name)
        parts.append(np.full(n, np.nan) if v is None else np.asarray(v, dtype=np.float64).reshape(n))
    return np.concatenate(parts)


def unpack(layout: Layout, vec: np.ndarray) -> dict[str, np.ndarray | None]:
    """Inverse of `pack`: name -> its values, or None when they were absent."""
    out: dict[str, np.ndarray | None] = {}
    i = 0
    for name, n in layout:
        part = np.asarray(vec[i:i + n], dtype=np.float64)
        out[name] = None if np.isnan(part).all() else part
        i += n
    return out


def blob(data: bytes) -> Any:
    """Bytes as one AnyValues cell (a binary arrow array of length 1)."""
    import pyarrow as pa
    return pa.array([data], type=pa.binary())


def blueprint() -> Any:
    """The viewer layout, built in one place: scene and events left; both camera views with the
    projected points, then the plots, right; setup in a tab."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(origin="world", name="scene (base frame, mm)"),
                rrb.TextLogView(origin=E_EVENTS, name="events"),
                row_shares=[3, 1],
            ),
            rrb.Vertical(
                rrb.Horizontal(
                    rrb.Spatial2DView(origin=E_CAM["left"], name="left"),
                    rrb.Spatial2DView(origin=E_CAM["right"], name="right"),
                ),
                rrb.Tabs(
                    rrb.TimeSeriesView(origin="plots", name="fitness / alpha / found"),
                    rrb.TimeSeriesView(origin="timing", name="timings (ms)"),
                    rrb.TimeSeriesView(origin="arm", contents=["arm/q_deg", "arm/setpoint_deg"],
                                       name="joints (deg)"),
                    rrb.TimeSeriesView(origin="arm/command_deg_s", name="joint velocity command (deg/s)"),
                    rrb.Spatial2DView(origin=E_MODEL, name="photo-model"),
                    rrb.TextDocumentView(origin="setup", name="setup"),
                ),
            ),
            column_shares=[1, 1],
        ),
        collapse_panels=False,
    )
