import math

import cv2
import numpy as np
import pytest

from photoservo.geometry import make_pose, pose_error
from photoservo.servo.control import (
    ServoParams,
    camera_twist,
    desired_camera_pose,
    flange_twist,
    yaw_error_deg,
)

PARAMS = ServoParams(hover_mm=400, k_position=2.0, k_rotation=2.0, feed_forward=1.0, max_speed_mm_s=300,
                     max_rotation_deg_s=60, damping=0.05, max_estimate_age_s=0.3, hold_tolerance_mm=10,
                     hold_tolerance_deg=3, hold_time_s=1.0, collect_height_mm=150, collect_speed_mm_s=80,
                     tool_dwell_s=0.5)


def rot(axis, deg):
    return cv2.Rodrigues(np.asarray(axis, float) * math.radians(deg))[0]


def test_desired_pose_looks_down_from_hover_height_along_long_axis():
    # target lying flat at (500, 100, -200), long axis (model x) yawed 30 deg, tilted by a wave
    R_model = rot([0, 0, 1], 30) @ rot([1, 0, 0], 180) @ rot([0, 1, 0], 8)
    T = make_pose(R_model, np.array([500.0, 100.0, -200.0]))
    T_des = desired_camera_pose(T, (120.0, 40.0), 400.0, np.eye(3))
    assert np.allclose(T_des[:3, 2], [0, 0, -1])  # optical axis straight down
    assert np.allclose(T_des[:3, 3], [500, 100, 200])  # hover above, wave tilt not chased
    heading = math.degrees(math.atan2(T_des[1, 0], T_des[0, 0]))
    assert heading == pytest.approx(30.0, abs=1e-6) or heading == pytest.approx(-150.0, abs=1e-6)
    assert np.allclose(np.linalg.det(T_des[:3, :3]), 1.0)


def test_long_axis_sign_follows_current_heading():
    T = make_pose(rot([0, 0, 1], 10), np.zeros(3))
    a = desired_camera_pose(T, (100, 20), 300, rot([0, 0, 1], 170))
    b = desired_camera_pose(T, (100, 20), 300, np.eye(3))
    assert a[0, 0] < 0 < b[0, 0]


def test_tall_target_uses_model_y_as_long_axis():
    T = make_pose(np.eye(3), np.zeros(3))
    T_des = desired_camera_pose(T, (20, 100), 300, np.eye(3))
    assert abs(T_des[1, 0]) == pytest.approx(1.0)


def test_rig_centre_not_left_camera_is_over_the_target():
    T = make_pose(np.eye(3), np.zeros(3))
    T_des = desired_camera_pose(T, (100, 20), 300, np.eye(3), T_left_centre=np.array([50.0, 0, 0]))
    centre = T_des[:3, :3] @ np.array([50.0, 0, 0]) + T_des[:3, 3]
    assert np.allclose(centre, [0, 0, 300])


def test_error_signs_and_law_drive_camera_towards_desired():
    T_cur = make_pose(rot([0, 0, 1], 0), np.array([0.0, 0, 0]))
    T_des = make_pose(rot([0, 0, 1], 10), np.array([50.0, -20.0, 5.0]))
    e = pose_error(T_des, T_cur)
    e_p, e_R = e[:3], e[3:]
    assert np.allclose(e_p, [50, -20, 5])
    assert e_R[2] == pytest.approx(math.radians(10))
    v, w = camera_twist(e, np.zeros(3), PARAMS)
    assert v @ e_p > 0 and w[2] > 0
    assert yaw_error_deg(T_cur, T_des) == pytest.approx(10.0)


def test_closed_loop_kinematic_camera_converges_and_feed_forward_removes_lag():
    dt, v_target = 0.004, np.array([30.0, 0.0, 0.0])
    for ff, bound in ((1.0, 0.5), (0.0, 30.0 / PARAMS.k_position + 1)):
        params = ServoParams(**{**PARAMS.__dict__, "feed_forward": ff})
        T_cam = make_pose(rot([1, 0, 0], 170) @ rot([0, 0, 1], 12), np.array([150.0, 40.0, 350.0]))
        p_t = np.zeros(3)
        for _ in range(int(8 / dt)):
            p_t = p_t + v_target * dt
            T_des = desired_camera_pose(make_pose(np.eye(3), p_t), (100, 20), 400, T_cam[:3, :3])
            v, w = camera_twist(pose_error(T_des, T_cam), v_target, params)
            T_cam = make_pose(cv2.Rodrigues(w * dt)[0] @ T_cam[:3, :3], T_cam[:3, 3] + v * dt)
        e_p = pose_error(T_des, T_cam)[:3]
        assert np.linalg.norm(e_p) < bound
        assert yaw_error_deg(T_cam, T_des) < 0.1


def test_flange_twist_transfers_rotation_lever_arm():
    tw = flange_twist(np.zeros(3), np.array([0, 0, 1.0]), np.zeros(3), np.array([100.0, 0, 0]))
    assert np.allclose(tw, [0, 100, 0, 0, 0, 1])


def test_speed_caps_hold():
    v, w = camera_twist(np.array([1e4, 0, 0, 0, 0, 3.0]), np.zeros(3), PARAMS)
    assert np.linalg.norm(v) == pytest.approx(300) and np.linalg.norm(w) == pytest.approx(math.radians(60))
