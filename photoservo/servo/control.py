"""Position-based visual servoing (method step 6): the desired camera pose is defined in the
target's horizontal frame, and a proportional law with velocity feed-forward gives the camera
twist, which is mapped to the flange and then to joint velocities by the arm's Jacobian.

Frames: everything here is in the arm's BASE frame (z up, mm, rad). A pose is a 4x4 homogeneous
transform named by its frames, T_a_b: X_a = T_a_b · X_b. The camera is the LEFT camera (OpenCV:
x right, y down, z forward). Pure maths: arrays in, arrays out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from photoservo.errors import InputError
from photoservo.geometry import make_pose

Z_UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class ServoParams:
    """[servo] config: the servo law, the desired relative pose and the hold/safety limits."""

    hover_mm: float  # rig centre height above the target along the vertical
    k_position: float  # proportional gain on position error (1/s)
    k_rotation: float  # proportional gain on orientation error (1/s)
    feed_forward: float  # 0..1, share of the tracker's target velocity fed forward
    max_speed_mm_s: float  # cap on the commanded camera speed
    max_rotation_deg_s: float  # cap on the commanded camera angular speed
    damping: float  # damped-least-squares lambda for the joint-velocity solve
    max_estimate_age_s: float  # older estimate -> controlled stop (the limit at a high frame rate, s)
    hold_tolerance_mm: float  # collection may start once the position error stays below this
    hold_tolerance_deg: float  # ... and the yaw error below this
    hold_time_s: float  # ... for this long
    collect_height_mm: float  # rig centre height above the target at which the tool fires
    collect_speed_mm_s: float  # descent/ascent speed during collection
    tool_dwell_s: float  # how long the tool output stays on at the bottom
    settle_s: float = 5.0  # scores (simulation): the hold error counts from this session time on (s)
    search_pose_deg: tuple[float, ...] = ()  # joints (deg) to move to when the creature leaves the view; () = hold
    estimate_age_frames: float = 2.0  # slower frames: the age limit is the latency plus this many frame intervals...
    max_estimate_age_cap_s: float = 1.0  # ...but never over this (s)

    def validate(self, where: str) -> None:
        for name in ("hover_mm", "k_position", "k_rotation", "max_speed_mm_s", "max_rotation_deg_s",
                     "max_estimate_age_s", "hold_time_s", "collect_height_mm", "collect_speed_mm_s",
                     "max_estimate_age_cap_s"):
            if getattr(self, name) <= 0:
                raise InputError(f"config key '{where}.{name}' must be > 0, got {getattr(self, name)}")
        if not 0.0 <= self.feed_forward <= 1.0:
            raise InputError(f"config key '{where}.feed_forward' must be in 0..1, got {self.feed_forward}")
        if len(self.search_pose_deg) not in (0, 7):
            raise InputError(f"config key '{where}.search_pose_deg' must be [] or 7 joint angles (deg), "
                             f"got {len(self.search_pose_deg)} numbers")
        if self.max_estimate_age_cap_s < self.max_estimate_age_s:
            raise InputError(f"config key '{where}.max_estimate_age_cap_s' must be >= max_estimate_age_s "
                             f"({self.max_estimate_age_s}), got {self.max_estimate_age_cap_s}")
        if self.collect_height_mm >= self.hover_mm:
            raise InputError(f"config key '{where}.collect_height_mm' must be below hover_mm ({self.hover_mm})")


def estimate_age_limit(params: ServoParams, latency_s: float, interval_s: float) -> float:
    """How old (s) an estimate may be for the arm to move on it: [servo] max_estimate_age_s, or,
    when frames come slower, the measured delivery latency (capture -> track at the controller,
    s) plus estimate_age_frames measured frame intervals (s) — an estimate is always at least
    the latency old and one interval more before the next one comes, and a late frame must not
    stop-start the arm — never more than max_estimate_age_cap_s.

    >>> p = ServoParams(600, 2, 2, 1, 250, 45, 0.05, 0.3, 10, 3, 1.5, 250, 80, 0.5)
    >>> estimate_age_limit(p, 0.05, 1 / 30), round(estimate_age_limit(p, 0.15, 1 / 3), 2)
    (0.3, 0.82)
    >>> estimate_age_limit(p, 0.3, 1.0)
    1.0
    """
    return min(max(params.max_estimate_age_s, latency_s + params.estimate_age_frames * interval_s),
               params.max_estimate_age_cap_s)


def long_axis(R_base_model: np.ndarray, size_mm: tuple[float, float]) -> np.ndarray:
    """The target's long axis in the base frame: model x if the model is wider than tall in the
    photo, else model y (model frame of DESIGN.md)."""
    return R_base_model[:, 0] if size_mm[0] >= size_mm[1] else R_base_model[:, 1]


def desired_camera_pose(
    T_base_model: np.ndarray,
    size_mm: tuple[float, float],
    hover_mm: float,
    R_base_cam_now: np.ndarray,
    T_left_centre: np.ndarray | None = None,
) -> np.ndarray:
    """Desired left-camera pose T_base_cam* (issue 5, Control).

    Defined in the target's horizontal frame: z up through the target's origin, x along the long
    axis projected onto the horizontal plane — so wave roll and pitch are not chased. The rig's
    centre (midpoint of the optical centres, `T_left_centre` = its offset in the left frame, mm)
    sits `hover_mm` above the target, the optical axes point straight down, and camera x is along
    the long axis, choosing the sign (the axis is 180-degree symmetric) nearest the camera's
    current x axis `R_base_cam_now[:, 0]`.
    """
    p_target = T_base_model[:3, 3]
    axis = long_axis(T_base_model[:3, :3], size_mm)
    axis = axis - Z_UP * (axis @ Z_UP)
    n = np.linalg.norm(axis)
    if n < 1e-9:  # target stood on end: keep the current heading
        axis = R_base_cam_now[:, 0] - Z_UP * (R_base_cam_now[:, 0] @ Z_UP)
        n = np.linalg.norm(axis)
        if n < 1e-9:
            axis, n = np.array([1.0, 0.0, 0.0]), 1.0
    x_c = axis / n
    if x_c @ R_base_cam_now[:, 0] < 0:
        x_c = -x_c
    z_c = -Z_UP  # optical axis down
    y_c = _cross(z_c, x_c)
    R_des = np.column_stack([x_c, y_c, z_c])
    offset = np.zeros(3) if T_left_centre is None else np.asarray(T_left_centre, dtype=float)
    p_centre = p_target + hover_mm * Z_UP
    return make_pose(R_des, p_centre - R_des @ offset)


def yaw_error_deg(T_base_cam: np.ndarray, T_base_cam_des: np.ndarray) -> float:
    """Angle (deg) between the current and desired camera x axes projected on the horizontal."""
    def heading(R: np.ndarray) -> float:
        return math.atan2(R[1, 0], R[0, 0])
    d = heading(T_base_cam_des[:3, :3]) - heading(T_base_cam[:3, :3])
    return math.degrees(abs((d + math.pi) % (2 * math.pi) - math.pi))


def camera_twist(e: np.ndarray, v_target: np.ndarray, params: ServoParams) -> tuple[np.ndarray, np.ndarray]:
    """PBVS law: v = k_p · e_p + f · v_target, ω = k_R · e_R, each clipped to its cap, where
    e = [e_p; e_R] = `geometry.pose_error(T_base_cam*, T_base_cam)` (mm, rad; base frame: the twist
    that reaches the desired pose in unit time) and v_target is the tracker's target velocity
    in the base frame (mm/s). Returns (v mm/s, ω rad/s)."""
    v = params.k_position * e[:3] + params.feed_forward * np.asarray(v_target, dtype=float)
    w = params.k_rotation * e[3:]
    v = _clip_norm(v, params.max_speed_mm_s)
    w = _clip_norm(w, math.radians(params.max_rotation_deg_s))
    return v, w


def flange_twist(v_cam: np.ndarray, w: np.ndarray, p_cam: np.ndarray, p_flange: np.ndarray) -> np.ndarray:
    """Rigid-body transfer of a twist from the camera origin to the flange origin (base frame):
    v_f = v_c + ω × (p_f − p_c), ω unchanged. Returns the 6-vector [v_f (mm/s); ω (rad/s)]."""
    return np.concatenate([v_cam + _cross(w, p_flange - p_cam), w])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b for 3-vectors, written out: np.cross costs ~0.1 ms, a tenth of a control period."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _clip_norm(x: np.ndarray, cap: float) -> np.ndarray:
    n = float(np.linalg.norm(x))
    return x * (cap / n) if n > cap else x
