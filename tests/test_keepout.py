"""Keep-out by volumes, checked continuously (servo/keepout.py)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from photoservo.config import load_config
from photoservo.errors import InputError
from photoservo.robot.pa10 import HOME_Q, load_limits
from photoservo.servo.keepout import FEATURES
from photoservo.servo.motion import Motion

PARAMS = load_config().motion
LIM = load_limits()


def _bump_path(amplitude: float, width_s: float, centre_s: float):
    """S2 leaning forward by `amplitude` rad in a smooth pulse (raised cosine, width_s long)
    around centre_s: q_at(t) and the pulse's peak S2 speed (rad/s)."""
    def q_at(t: float) -> np.ndarray:
        q = HOME_Q.copy()
        u = (t - centre_s) / width_s
        if abs(u) < 0.5:
            q[1] += amplitude * 0.5 * (1.0 + math.cos(2.0 * math.pi * u))
        return q

    return q_at, amplitude * math.pi / width_s


def test_a_dip_between_samples_is_caught():
    # the rig box bottom is 54.7 mm above the plane at home; a 5 ms S2 pulse of 0.2 rad between
    # the 0.02 s samples (at 0.01 s) lowers it ~150 mm through the plane and back
    m = Motion(dataclasses.replace(PARAMS, z_min_mm=400.0), LIM)
    k = m.keepout
    q_at, v_peak = _bump_path(0.2, 0.005, 0.01)
    v = np.zeros(7)
    v[1] = v_peak
    samples = np.array([q_at(t) for t in np.arange(0.0, 0.1001, 0.02)])
    assert k.violation(samples) == ""  # every sample is clear: the old check passed this path
    assert k.violation(q_at(0.01)) != ""  # the middle of the pulse is under water
    why = k.sweep_violation(q_at, 0.1, v)
    assert "camera rig box would go below the water plane" in why and "t = 0.0" in why, why


def test_a_clear_path_is_proven_clear_and_a_grazing_one_refused():
    m = Motion(dataclasses.replace(PARAMS, z_min_mm=400.0), LIM)
    k = m.keepout
    q_at, v_peak = _bump_path(0.02, 0.2, 0.1)  # slow and small: stays ~40 mm above
    v = np.zeros(7)
    v[1] = v_peak
    assert k.sweep_violation(q_at, 0.2, v) == ""
    # the same clear path with an absurd speed bound cannot be proven clear: refused, not passed
    assert "not proven" in k.sweep_violation(q_at, 0.2, v * 1e6)


def test_volumes_catch_what_the_points_missed():
    # elbow, wrist, flange and tool all above a plane at 500 mm at home (lowest: the flange at
    # 624.7), but the camera rig hangs under the flange: its box reaches 454.7 mm
    m = Motion(dataclasses.replace(PARAMS, z_min_mm=500.0), LIM)
    P = dict(zip(FEATURES, m.keepout.features(HOME_Q)[0]))
    assert min(P[n][2] for n in ("elbow", "wrist", "flange", "tool")) > 500.0
    with pytest.raises(InputError, match="camera rig box would go below the water plane"):
        m.check_target(HOME_Q)
    # a link capsule: the wrist's 60 mm radius around the flange end (624.7 mm), the rig box
    # moved out of the way (200 mm above the flange at home)
    thin = dataclasses.replace(PARAMS, z_min_mm=600.0, rig_box_min_mm=(-1.0, -1.0, -200.0),
                               rig_box_max_mm=(1.0, 1.0, -199.0))
    q = HOME_Q.copy()
    assert Motion(dataclasses.replace(thin, link_radii_mm=(0.0, 0.0, 0.0)), LIM).keepout_violation(q) == ""
    why = Motion(thin, LIM).keepout_violation(q)
    assert why.startswith("the flange would go below the water plane (35.3 mm under"), why


def test_a_move_whose_path_dips_is_refused_before_it_starts():
    # S3 swinging from -170 to +170 deg sweeps the bent forearm down through S3 = 0; the check
    # of the planned path names the volume and the time
    m = Motion(dataclasses.replace(PARAMS, z_min_mm=300.0), LIM)
    start = np.radians([0, 45, -170, 90, 0, 0, 0])
    target = np.radians([0, 45, 170, 90, 0, 0, 0])
    with pytest.raises(InputError, match=r"the path to it: the .* would go below the water plane .* at t = "):
        m.check_target(target, start)


def test_volume_keys_are_bounded():
    for key, v in (("link_radii_mm", (80.0, float("inf"), 60.0)), ("rig_box_max_mm", (110.0, 70.0, -5.0))):
        with pytest.raises(InputError, match=key):
            dataclasses.replace(PARAMS, **{key: v}).validate("motion")
