"""PA-10 kinematics: FK against an independent product of exponentials, the Jacobian against
finite differences, IK round trips, wide-range joints, sign conventions and the limits file."""

import doctest
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoservo.errors import InputError
from photoservo.robot import pa10
from photoservo.robot.pa10 import (
    HOME_Q,
    JOINT_NAMES,
    IKError,
    PA10Limits,
    dls_step,
    fk,
    fk_frames,
    ik,
    jacobian,
    load_limits,
    nearest_equivalent,
    tool_offset,
)
from photoservo.geometry import make_pose, pose_error, rotation_log

LIM = load_limits()


def _skew(w):
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def _exp_twist(w, p, theta):
    """exp of a unit revolute screw (axis w through point p) by angle theta (Lynch & Park 3.51)."""
    W = _skew(w)
    R = np.eye(3) + math.sin(theta) * W + (1 - math.cos(theta)) * W @ W
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = (np.eye(3) - R) @ p
    return T


def _fk_poe(q):
    """Independent model from the arm's physical layout at q = 0 (straight up): rolls about +z,
    pitches about +y, axes through the shoulder (315), elbow (765) and wrist (1265) heights."""
    z, y = np.array([0.0, 0, 1]), np.array([0.0, 1, 0])
    axes = [(z, 0), (y, 315), (z, 315), (y, 765), (z, 765), (y, 1265), (z, 1265)]
    T = np.eye(4)
    for (w, h), th in zip(axes, q):
        T = T @ _exp_twist(w, np.array([0.0, 0.0, h]), th)
    M = np.eye(4)
    M[2, 3] = 1345.0
    return T @ M


def _random_q(rng, n):
    return rng.uniform(LIM.q_min, LIM.q_max, size=(n, 7))


def test_fk_at_zero_is_straight_up():
    T = fk(np.zeros(7))
    np.testing.assert_allclose(T[:3, :3], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], [0, 0, 315 + 450 + 500 + 80], atol=1e-9)
    F = fk_frames(np.zeros(7))
    assert F.shape == (8, 4, 4)
    np.testing.assert_allclose(F[0], np.eye(4))
    np.testing.assert_allclose(F[:, 0, 3], 0, atol=1e-9)
    assert np.all(np.diff(F[:, 2, 3]) >= 0)  # every link frame at or above the previous one


def test_fk_matches_product_of_exponentials():
    rng = np.random.default_rng(1)
    for q in _random_q(rng, 50):
        np.testing.assert_allclose(fk(q), _fk_poe(q), atol=1e-9)


def test_jacobian_matches_finite_differences_with_and_without_tool():
    rng = np.random.default_rng(2)
    T_tool = make_pose(_exp_twist(np.array([1.0, 0, 0]), np.zeros(3), 0.4)[:3, :3], (20.0, -30.0, 150.0))
    h = 1e-6
    for q in _random_q(rng, 20):
        for tool in (None, T_tool):
            J = jacobian(q, tool)
            T0 = fk(q, tool)
            Jn = np.empty((6, 7))
            for i in range(7):
                dq = np.zeros(7)
                dq[i] = h
                Tp, Tm = fk(q + dq, tool), fk(q - dq, tool)
                Jn[:3, i] = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
                Jn[3:, i] = (rotation_log(Tp[:3, :3] @ T0[:3, :3].T) - rotation_log(Tm[:3, :3] @ T0[:3, :3].T)) / (2 * h)
            np.testing.assert_allclose(J, Jn, atol=1e-5 * 1345)


def test_sign_conventions():
    # positive S2 leans the arm toward base +x; positive S1 then swings it toward +y (right hand about z)
    q = np.zeros(7)
    q[1] = math.radians(20)
    assert fk(q)[0, 3] > 0
    q[0] = math.radians(30)
    p = fk(q)[:3, 3]
    assert p[1] > 0 and math.isclose(math.degrees(math.atan2(p[1], p[0])), 30.0, abs_tol=1e-9)
    # positive E1 and W1 also pitch toward +x at zero; S3, E2, W2 roll the flange about +z when straight up
    for j in (3, 5):
        q = np.zeros(7)
        q[j] = 0.1
        assert fk(q)[0, 3] > 0
    for j in (2, 4, 6):
        q = np.zeros(7)
        q[j] = 0.3
        assert np.allclose(rotation_log(fk(q)[:3, :3]), [0, 0, 0.3])
    # the Jacobian's angular rows are in the base frame: at q = 0 joint 1 spins about base +z
    np.testing.assert_allclose(jacobian(np.zeros(7))[3:, 0], [0, 0, 1])


def test_home_is_bent_looking_down_and_well_conditioned():
    T = fk(HOME_Q)
    np.testing.assert_allclose(T[:3, 2], [0, 0, -1], atol=1e-12)  # flange z (camera axis) points down
    assert T[2, 3] > 300 and T[0, 3] > 500
    LIM.check(HOME_Q)
    J = jacobian(HOME_Q)
    J[:3] /= pa10.LENGTH_REF_MM
    assert np.linalg.svd(J, compute_uv=False)[-1] > 0.1
    assert np.linalg.svd(jacobian(np.zeros(7)), compute_uv=False)[-1] < 1e-9  # straight up is singular


def test_rotation_log_round_trip_including_near_pi():
    rng = np.random.default_rng(3)
    for angle in (0.0, 1e-8, 0.3, 2.0, math.pi - 1e-6, math.pi):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        R = _exp_twist(n, np.zeros(3), angle)[:3, :3]
        w = rotation_log(R)
        np.testing.assert_allclose(_exp_twist(w / max(np.linalg.norm(w), 1e-300), np.zeros(3), np.linalg.norm(w))[:3, :3], R, atol=1e-7)


def test_dls_step_follows_twist_and_nullspace_does_not_disturb_it():
    q = HOME_Q + 0.1
    twist = np.array([10.0, -5.0, 3.0, 0.01, 0.02, -0.01])
    dq = dls_step(q, twist, damping=0.0, k_null=0.0)
    np.testing.assert_allclose(jacobian(q) @ dq, twist, atol=1e-9)
    dq_n = dls_step(q, twist, damping=0.0, k_null=1.0)
    np.testing.assert_allclose(jacobian(q) @ dq_n, twist, atol=1e-8)
    assert not np.allclose(dq, dq_n)
    # the null-space motion alone moves toward home (positive projection on q_home - q)
    pull = dls_step(q, np.zeros(6), damping=0.0, k_null=1.0)
    assert pull @ (HOME_Q - q) > 0
    # held joints do not move
    free = np.ones(7, bool)
    free[3] = False
    assert dls_step(q, twist, 0.01, free=free, k_null=1.0)[3] == 0.0


def test_ik_round_trips_random_reachable_poses():
    rng = np.random.default_rng(4)
    T_tool = tool_offset(120.0)
    for k, q_true in enumerate(_random_q(rng, 30)):
        tool = T_tool if k % 2 else None
        T = fk(q_true, tool)
        q0 = q_true + rng.normal(0, 0.3, 7)
        q = ik(T, q0, LIM, T_flange_tool=tool)
        e = pose_error(T, fk(q, tool))
        assert np.linalg.norm(e[:3]) < 0.05 and np.linalg.norm(e[3:]) < 1e-4
        assert np.all(q >= LIM.q_min) and np.all(q <= LIM.q_max)


def test_ik_from_home_success_rate():
    rng = np.random.default_rng(5)
    ok = 0
    qs = _random_q(rng, 30)
    for q_true in qs:
        try:
            ik(fk(q_true), HOME_Q, LIM)
            ok += 1
        except IKError:
            pass
    assert ok >= 29  # 300 seeded poses: 100 % (benchmarks/kinematics_motion.py)


def test_ik_unreachable_raises():
    with pytest.raises(IKError, match="did not converge"):
        ik(make_pose(np.eye(3), (3000.0, 0, 0)), HOME_Q, LIM, max_iter=50)


def test_ik_respects_a_narrowed_joint_range():
    lim = PA10Limits(q_min=LIM.q_min, q_max=np.where(np.arange(7) == 3, math.radians(70), LIM.q_max),
                     dq_max=LIM.dq_max, ddq_max=LIM.ddq_max, dddq_max=LIM.dddq_max)
    q_true = HOME_Q.copy()
    q_true[3] = math.radians(65)
    q_true[1] = math.radians(35)
    q = ik(fk(q_true), HOME_Q, lim)
    assert q[3] <= math.radians(70) + 1e-12


def test_wide_range_joints_take_nearest_equivalent():
    q = np.zeros(7)
    q[4] = math.radians(-170)  # E2
    q[6] = math.radians(100)  # W2
    ref = np.zeros(7)
    ref[4] = math.radians(170)
    ref[6] = math.radians(-200)
    out = nearest_equivalent(q, ref, LIM)
    assert math.isclose(math.degrees(out[4]), 190.0)
    # -260 is outside +-255, so W2 stays at 100
    assert math.isclose(math.degrees(out[6]), 100.0)
    # joints narrower than a turn never wrap
    q2 = np.radians([170, 0, 0, 0, 0, 0, 0])
    assert nearest_equivalent(q2, np.radians([-170, 0, 0, 0, 0, 0, 0]), LIM)[0] == q2[0]
    # IK keeps the branch nearest the start for the wrist roll
    q_true = HOME_Q.copy()
    q_true[6] = math.radians(-150)
    q0 = q_true.copy()
    q0[6] = math.radians(210)
    q = ik(fk(q_true), q0, LIM)
    assert math.isclose(math.degrees(q[6]), 210.0, abs_tol=1e-3)


def test_limits_file_and_check():
    assert math.isclose(math.degrees(LIM.q_max[4]), 255.0) and math.isclose(math.degrees(LIM.q_min[1]), -91.0)
    assert np.all(LIM.dq_max > 0) and np.all(LIM.dddq_max > 0)
    with pytest.raises(InputError, match=r"joint E1 = 140.00 deg is outside its range \[-137.0, 137.0\]"):
        LIM.check(np.radians([0, 0, 0, 140, 0, 0, 0]))
    assert JOINT_NAMES[3] == "E1"


def test_bad_limits_file_names_the_key(tmp_path):
    text = (pa10.configs_dir() / "pa10.toml").read_text()
    p = tmp_path / "pa10.toml"
    p.write_text(text.replace("dq_max_deg = [45.0,", "dq_max_deg = [-45.0,"))
    with pytest.raises(InputError, match=r"pa10.toml: config key 'joints.dq_max_deg\[0\]' \(S1\) must be > 0"):
        load_limits(p)
    p.write_text(text.replace("q_max_deg = [177.0,", "q_max_deg = [-178.0,"))
    with pytest.raises(InputError, match=r"joints.q_max_deg\[0\]"):
        load_limits(p)
    p.write_text(text.replace("ddq_max_deg", "ddq_maxdeg"))
    with pytest.raises(InputError, match="unknown key 'joints.ddq_maxdeg'"):
        load_limits(p)


def test_docstring_examples_run():
    assert doctest.testmod(pa10).failed == 0


@settings(max_examples=200, deadline=None)
@given(q=st.lists(st.floats(-4.4, 4.4), min_size=7, max_size=7),
       ref=st.lists(st.floats(-4.4, 4.4), min_size=7, max_size=7))
def test_nearest_equivalent_properties(q, ref):
    q, ref = np.array(q), np.array(ref)
    out = nearest_equivalent(q, ref, LIM)
    k = (out - q) / (2 * np.pi)
    np.testing.assert_allclose(k, np.round(k), atol=1e-9)  # same angle
    inside = (q >= LIM.q_min) & (q <= LIM.q_max)
    assert np.all((out >= LIM.q_min - 1e-12) & (out <= LIM.q_max + 1e-12) | ~inside)
    for dk in (-1, 1):  # no other in-range equivalent is nearer the reference
        alt = out + 2 * np.pi * dk
        ok = (alt >= LIM.q_min) & (alt <= LIM.q_max) & inside
        assert np.all(np.abs(alt - ref)[ok] >= np.abs(out - ref)[ok] - 1e-9)


def test_pose_error_is_the_twist_that_reaches_the_target():
    rng = np.random.default_rng(8)
    for _ in range(20):
        T = fk(rng.uniform(LIM.q_min, LIM.q_max))
        T_star = fk(rng.uniform(LIM.q_min, LIM.q_max))
        e = pose_error(T_star, T)
        w = e[3:]
        angle = np.linalg.norm(w)
        R = _exp_twist(w / angle, np.zeros(3), angle)[:3, :3] @ T[:3, :3]  # rotate by w in the BASE frame
        np.testing.assert_allclose(R, T_star[:3, :3], atol=1e-9)
        np.testing.assert_allclose(T[:3, 3] + e[:3], T_star[:3, 3], atol=1e-9)


def test_fk_frames_of_a_batch_are_those_of_each_configuration():
    """The compiled kernel (robot/pa10_kernel.py) on a batch (N, 7) gives each row's frames, and
    every frame of a row is the product of the DH transforms up to it (Rz · Tz · Tx · Rx written
    as separate matrices here)."""
    from photoservo.robot.pa10 import DH_A_MM, DH_ALPHA, DH_D_MM

    def rot(axis, th):
        c, s = math.cos(th), math.sin(th)
        T = np.eye(4)
        i, j = {"x": (1, 2), "z": (0, 1)}[axis]
        T[i, i], T[i, j], T[j, i], T[j, j] = c, -s, s, c
        return T

    def trans(axis, v):
        T = np.eye(4)
        T["xyz".index(axis), 3] = v
        return T

    Q = _random_q(np.random.default_rng(7), 40)
    F = fk_frames(Q)
    assert F.shape == (40, 8, 4, 4)
    for q, Fq in zip(Q, F):
        np.testing.assert_array_equal(fk_frames(q), Fq)
        T = np.eye(4)
        for i in range(7):
            T = T @ rot("z", q[i]) @ trans("z", DH_D_MM[i]) @ trans("x", DH_A_MM[i]) @ rot("x", DH_ALPHA[i])
            np.testing.assert_allclose(Fq[i + 1], T, atol=1e-9)


def test_fk_frames_compiles_one_kernel_for_every_input():
    """Read-only joints (a module constant, a decoded state report) and writable ones, single and
    batched, reach the kernel as one type: the warm start's compile covers the control loop's
    calls (a second compile there stalled the first run's loop: a watchdog stop at ~3 s)."""
    from photoservo.robot.pa10_kernel import fk_frames_kernel

    q = np.asarray(pa10.HOME_Q, float)
    ro = np.frombuffer(q.tobytes())
    assert not ro.flags.writeable
    for arg in (ro, q.copy(), np.stack([q, q]), np.asfortranarray(np.stack([q, q]))[:, ::1]):
        pa10.fk_frames(arg)
    assert len(fk_frames_kernel.signatures) == 1, fk_frames_kernel.signatures
    np.testing.assert_array_equal(pa10.fk_frames(ro), pa10.fk_frames(q.copy()))
