"""robot/arm.py: the one JointHistory ("joint state at time t") and the Arm interface that the
serial link and the lockstep arm implement."""

import numpy as np
import pytest

from photoservo.robot.arm import Arm, JointHistory
from photoservo.robot.link import Link
from photoservo.sim.arm import LockstepArm


def test_interpolates_extrapolates_a_little_and_refuses_outside():
    h = JointHistory(keep_s=1.0, ahead_s=0.01)
    h.append(0.0, np.zeros(7), np.ones(7))
    h.append(0.1, np.full(7, 0.2), np.full(7, 3.0))
    q, dq = h.at(0.025)
    assert q == pytest.approx(np.full(7, 0.05)) and dq == pytest.approx(np.full(7, 1.5))
    q, dq = h.at(0.105)  # 5 ms after the newest state: extrapolated with its velocity
    assert q == pytest.approx(np.full(7, 0.2 + 3.0 * 0.005)) and dq == pytest.approx(np.full(7, 3.0))
    for t in (-0.001, 0.111):
        with pytest.raises(LookupError):
            h.at(t)


def test_keeps_only_keep_s_of_states():
    h = JointHistory(keep_s=0.5)
    for k in range(11):
        h.append(0.1 * k, np.full(7, float(k)))
    assert len(h) == 6 and h.span == pytest.approx((0.5, 1.0))
    with pytest.raises(LookupError):
        h.at(0.45)


def test_from_samples_drops_duplicates_and_differentiates():
    t = np.array([0.0, 0.1, 0.1, 0.2])
    q = np.outer([0.0, 0.1, 0.1, 0.3], np.ones(7))
    h = JointHistory.from_samples(t, q)
    assert len(h) == 3
    q_mid, dq_mid = h.at(0.1)
    assert q_mid == pytest.approx(np.full(7, 0.1)) and dq_mid == pytest.approx(np.full(7, 1.5))  # (0.3 - 0) / 0.2


def test_link_and_lockstep_arm_are_arms():
    assert issubclass(Link, Arm) and issubclass(LockstepArm, Arm)
    assert not Arm.__abstractmethods__ - set(vars(Link)) and not Arm.__abstractmethods__ - set(vars(LockstepArm))
