"""Is a frame's best pose a measurement? (issue 10: tracking that holds). The tests the tracker
(vision/tracker.py) applies besides detection: how much of the creature the cameras see at that
pose (`visible_shares`), and whether the pose can be a creature floating on known water
(`water_gate`). A frame that fails one is a miss, not a measurement.
"""

from __future__ import annotations

import math
import numpy as np

from photoservo.vision.photo_model import PhotoModel
from photoservo.vision.rig import Rig, project_points


def visible_shares(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, rig: Rig) -> tuple[float, float]:
    """Share of the model's inner points S_in that land inside the left and the right image
    (pixel centres within the sensor, in front of the camera) at one pose: R (3,3), t (3,) mm
    (model in the left camera frame, method step 2), alpha px/mm."""
    uv = np.asarray(model.inner_uv, np.float64) / alpha
    X_left = uv @ np.asarray(R)[:, :2].T + np.asarray(t).reshape(3)
    shares = []
    for cam, X in ((rig.left, X_left), (rig.right, X_left @ rig.R.T + rig.T)):
        with np.errstate(invalid="ignore", over="ignore"):
            p = project_points(X, cam)
            inside = (p[:, 0] >= -0.5) & (p[:, 0] < cam.width - 0.5) & (p[:, 1] >= -0.5) & (p[:, 1] < cam.height - 0.5)
        shares.append(float(np.mean(inside)) if len(inside) else 0.0)
    return shares[0], shares[1]


def water_gate(T_base_model: np.ndarray, water_z_mm: float, margin_mm: float, max_tilt_deg: float) -> str:
    """The water plane's plausibility test of a measured pose (base frame, z up, mm): 'plane'
    when the model origin is farther than margin_mm from the plane z = water_z_mm, 'tilt' when
    the model normal (model z, down into the water for a creature lying face-up) is farther than
    max_tilt_deg from straight down; '' when both hold or the plane is unknown (nan).

    >>> T = np.diag([1.0, -1.0, -1.0, 1.0]); T[2, 3] = -100.0   # face-up on the water
    >>> water_gate(T, -100.0, 40.0, 25.0), water_gate(T, -160.0, 40.0, 25.0), water_gate(T, float("nan"), 40.0, 25.0)
    ('', 'plane', '')
    """
    off, tilted = water_gates(np.array([T_base_model[2, 3]]), np.array([T_base_model[2, 2]]), water_z_mm,
                              margin_mm, max_tilt_deg)
    return "plane" if off[0] else "tilt" if tilted[0] else ""


def on_water(T_base_left: np.ndarray, R: np.ndarray, t: np.ndarray, water_z_mm: float, margin_mm: float,
             max_tilt_deg: float) -> np.ndarray:
    """`water_gate` of many poses at once: (N,) True where a pose (R (N,3,3), t (N,3) mm: model
    in the left camera at T_base_left) passes both tests (all True on unknown water). The tracker
    searches only such poses (vision/tracker.py): a search left a generation or two per frame
    otherwise settles on a tilted or sunken pose that scores well and is no measurement."""
    z = t @ T_base_left[2, :3] + T_base_left[2, 3]
    normal_z = R[:, :, 2] @ T_base_left[2, :3]
    off, tilted = water_gates(z, normal_z, water_z_mm, margin_mm, max_tilt_deg)
    return ~(off | tilted)


def water_gates(z_mm: np.ndarray, normal_z: np.ndarray, water_z_mm: float, margin_mm: float,
                max_tilt_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """The two water tests on model origins' heights z_mm and model normals' z components
    normal_z (base frame, z up): (off the plane by more than margin_mm, tilted past
    max_tilt_deg); both all False when the plane is unknown (nan)."""
    if not math.isfinite(water_z_mm):
        return np.zeros(len(z_mm), bool), np.zeros(len(z_mm), bool)
    off = np.abs(z_mm - water_z_mm) > margin_mm
    return off, ~off & (-normal_z < math.cos(math.radians(max_tilt_deg)))  # normal . (0, 0, -1)
