"""Mitsubishi PA-10 kinematics (method step 6: the arm that carries the stereo rig) and its limits.

Standard (distal) Denavit-Hartenberg as in Spong and Corke's DHRobot, not Craig's modified DH;
joint i moves frame i-1 -> i:

    A_i(q_i) = Rz(theta_i) · Tz(d_i) · Tx(a_i) · Rx(alpha_i),   theta_i = q_i

    a     = 0 for every joint
    d     = (315, 0, 450, 0, 500, 0, 80) mm
    alpha = (-90, 90, -90, 90, -90, 90, 0) deg

Joint signs and zero offsets: q_i IS the DH angle theta_i (zero offset 0 for every joint),
positive by the right-hand rule about z_{i-1}. At q = 0 the arm stands straight up, frames 2, 4,
6 and the flange have the base orientation (the twists cancel in pairs) and the flange origin is
at z = 315 + 450 + 500 + 80 = 1345 mm. Joints S1, S3, E2, W2 roll about the link's long axis
(+z at q = 0); S2, E1, W1 pitch (about base +y at q = 0, so positive S2 leans the arm toward
base +x).

Frames and units: base frame z up, millimetres and radians. Poses are 4x4 homogeneous transforms
named by their frames, T_a_b with X_a = T_a_b · X_b. The flange frame is frame 7 (the tool
plate); a tool or the rig's left camera is attached with T_flange_tool / T_flange_camera
(`Rig.T_flange_left()` gives the latter from the rig's [hand_eye] table); pose builders and the
pose error live in photoservo/geometry.py.

Limits (joint ranges, speed, acceleration, jerk) live in configs/pa10.toml, in degrees there and
in radians in `PA10Limits`.

>>> bool(np.allclose(fk(np.zeros(7))[:3, 3], [0, 0, 1345]))
True
>>> T = fk(HOME_Q)                       # bent home: flange in front of the base, z axis down
>>> bool(np.allclose(T[:3, 3], [725, 0, 624.71], atol=0.01)), bool(np.allclose(T[:3, 2], [0, 0, -1]))
(True, True)
>>> q = ik(fk(HOME_Q + 0.1), HOME_Q, load_limits())
>>> bool(np.linalg.norm(pose_error(fk(HOME_Q + 0.1), fk(q))[:3]) < 0.05)
True
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from photoservo.errors import InputError
from photoservo.geometry import make_pose, pose_error
from photoservo.tomlconf import build_dataclass, configs_dir, read_toml

N_JOINTS = 7
JOINT_NAMES = ("S1", "S2", "S3", "E1", "E2", "W1", "W2")

DH_A_MM = np.zeros(N_JOINTS)
DH_D_MM = np.array([315.0, 0.0, 450.0, 0.0, 500.0, 0.0, 80.0])
DH_ALPHA = np.radians([-90.0, 90.0, -90.0, 90.0, -90.0, 90.0, 0.0])
_CA = np.round(np.cos(DH_ALPHA), 15)
_SA = np.round(np.sin(DH_ALPHA), 15)

#: Home posture (rad): shoulder leaning 30 deg forward, elbow bent 60 deg, wrist pitched 90 deg,
#: so the flange z axis (and a camera looking along it) points straight down at the water,
#: the flange about 725 mm in front of the base and 625 mm above it. No two roll axes are
#: aligned (S2, E1, W1 all away from 0), so the Jacobian has full rank 6 there.
HOME_Q = np.radians([0.0, 30.0, 0.0, 60.0, 0.0, 90.0, 0.0])
HOME_Q.setflags(write=False)

#: Reference length (mm) that puts position and orientation on one scale in the least-squares
#: solves: a 1 rad orientation error weighs as much as a LENGTH_REF_MM position error.
LENGTH_REF_MM = 1000.0


# --------------------------------------------------------------------------------------------
# limits


def _joint_array(values, name: str) -> np.ndarray:
    a = np.array(values, dtype=float).reshape(-1)
    if a.shape != (N_JOINTS,):
        raise InputError(f"PA10Limits.{name}: expected {N_JOINTS} values, got {a.size}")
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class PA10Limits:
    """Per-joint limits in RADIANS (order S1 S2 S3 E1 E2 W1 W2), each a read-only array of 7:
    joint range [q_min, q_max] (rad), speed dq_max (rad/s), acceleration ddq_max (rad/s^2) and
    jerk dddq_max (rad/s^3). Build from configs/pa10.toml with `load_limits()`."""

    q_min: np.ndarray
    q_max: np.ndarray
    dq_max: np.ndarray
    ddq_max: np.ndarray
    dddq_max: np.ndarray

    def __post_init__(self) -> None:
        for name in ("q_min", "q_max", "dq_max", "ddq_max", "dddq_max"):
            object.__setattr__(self, name, _joint_array(getattr(self, name), name))
        for j, n in enumerate(JOINT_NAMES):
            if not self.q_min[j] < self.q_max[j]:
                raise InputError(f"PA10Limits: joint {n} range is empty ({self.q_min[j]} .. {self.q_max[j]})")
            for name in ("dq_max", "ddq_max", "dddq_max"):
                if not getattr(self, name)[j] > 0:
                    raise InputError(f"PA10Limits.{name}: joint {n} must be > 0")

    def check(self, q: np.ndarray, what: str = "joint target") -> None:
        """Raise InputError naming the first joint of `q` (rad) outside its range, in degrees."""
        q = np.asarray(q, dtype=float)
        if q.shape != (N_JOINTS,):
            raise InputError(f"{what}: expected {N_JOINTS} joint values, got {q.size}")
        for j, n in enumerate(JOINT_NAMES):
            if not np.isfinite(q[j]):
                raise InputError(f"{what}: joint {n} is not a finite number ({q[j]})")
            if not self.q_min[j] <= q[j] <= self.q_max[j]:
                raise InputError(
                    f"{what}: joint {n} = {math.degrees(q[j]):.2f} deg is outside its range "
                    f"[{math.degrees(self.q_min[j]):.1f}, {math.degrees(self.q_max[j]):.1f}] deg")


@dataclass(frozen=True)
class _JointsTable:
    """[joints] table of configs/pa10.toml (degrees)."""

    names: tuple[str, ...]
    q_min_deg: tuple[float, ...]
    q_max_deg: tuple[float, ...]
    dq_max_deg: tuple[float, ...]
    ddq_max_deg: tuple[float, ...]
    dddq_max_deg: tuple[float, ...]

    def validate(self, where: str) -> None:
        if tuple(self.names) != JOINT_NAMES:
            raise InputError(f"config key '{where}.names' must be {list(JOINT_NAMES)}, got {list(self.names)}")
        for key in ("q_min_deg", "q_max_deg", "dq_max_deg", "ddq_max_deg", "dddq_max_deg"):
            vals = getattr(self, key)
            if len(vals) != N_JOINTS:
                raise InputError(f"config key '{where}.{key}': expected {N_JOINTS} values, got {len(vals)}")
            if key != "q_min_deg" and key != "q_max_deg":
                for j, v in enumerate(vals):
                    if not v > 0:
                        raise InputError(f"config key '{where}.{key}[{j}]' ({JOINT_NAMES[j]}) must be > 0, got {v}")
        for j in range(N_JOINTS):
            if not self.q_min_deg[j] < self.q_max_deg[j]:
                raise InputError(f"config key '{where}.q_max_deg[{j}]' ({JOINT_NAMES[j]}) must exceed "
                                 f"q_min_deg[{j}] ({self.q_min_deg[j]}), got {self.q_max_deg[j]}")


@dataclass(frozen=True)
class _PA10File:
    joints: _JointsTable


def load_limits(path: str | os.PathLike | None = None) -> PA10Limits:
    """Read and validate a PA-10 limits file (default: configs/pa10.toml). Degrees in the file,
    radians in the result. A bad file is an InputError naming the file and the key."""
    p = Path(path) if path is not None else configs_dir() / "pa10.toml"
    doc = read_toml(p)
    try:
        f = build_dataclass(_PA10File, doc, "")
    except InputError as e:
        raise InputError(f"{p}: {e}") from None
    t = f.joints
    return PA10Limits(q_min=np.radians(t.q_min_deg), q_max=np.radians(t.q_max_deg),
                      dq_max=np.radians(t.dq_max_deg), ddq_max=np.radians(t.ddq_max_deg),
                      dddq_max=np.radians(t.dddq_max_deg))


# --------------------------------------------------------------------------------------------
# forward kinematics and Jacobian


def tool_offset(z_mm: float) -> np.ndarray:
    """T_flange_tool for a straight tool of length z_mm along the flange z axis (a net, a gripper)."""
    return make_pose(np.eye(3), (0.0, 0.0, z_mm))


def _q(q) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.shape != (N_JOINTS,):
        raise ValueError(f"expected {N_JOINTS} joint angles, got shape {q.shape}")
    return q


def fk_frames(q) -> np.ndarray:
    """All link frames in the base frame, (8, 4, 4): [0] the base (identity), [i] = A_1 ... A_i,
    [7] the flange. Frame i-1's z axis is joint i's axis. Used to draw the arm and by `jacobian`.
    A batch of configurations (N, 7) gives (N, 8, 4, 4). Computed by the compiled kernel
    (pa10_kernel.py)."""
    from photoservo.robot.pa10_kernel import fk_frames_kernel

    q = np.asarray(q, dtype=float)
    if q.shape[-1:] != (N_JOINTS,) or q.ndim > 2:
        raise ValueError(f"expected {N_JOINTS} joint angles (or N x {N_JOINTS}), got shape {q.shape}")
    # always a fresh, writable C array: a read-only one (a constant, a decoded buffer) is another
    # type to numba, and compiling it a second time inside the control loop stalls the loop
    Q = np.array(q.reshape(-1, N_JOINTS), order="C")
    frames = np.empty((len(Q), N_JOINTS + 1, 4, 4))
    fk_frames_kernel(Q, DH_A_MM, DH_D_MM, _CA, _SA, frames)
    return frames.reshape(q.shape[:-1] + (N_JOINTS + 1, 4, 4))


def fk(q, T_flange_tool: np.ndarray | None = None) -> np.ndarray:
    """Forward kinematics: T_base_flange (4x4, mm) at joint angles q (rad), or T_base_tool =
    T_base_flange · T_flange_tool when a tool (or camera) frame is given."""
    T = fk_frames(q)[-1]
    return T if T_flange_tool is None else T @ T_flange_tool


def jacobian(q, T_flange_tool: np.ndarray | None = None) -> np.ndarray:
    """Geometric Jacobian J (6x7) with [v; omega] = J · dq.

    Reference point: the flange origin, or the tool origin when T_flange_tool is given.
    Frame: both v (mm/s per rad/s) and omega (rad/s per rad/s) are expressed in the BASE frame.
    Column i (revolute joint about z_{i-1} through o_{i-1}):
        J_v,i = z_{i-1} × (p - o_{i-1}),    J_w,i = z_{i-1}.
    """
    F = fk_frames(q)
    p = F[-1][:3, 3] if T_flange_tool is None else (F[-1] @ T_flange_tool)[:3, 3]
    z = F[:-1, :3, 2]
    o = F[:-1, :3, 3]
    J = np.empty((6, N_JOINTS))
    r = p - o
    J[0] = z[:, 1] * r[:, 2] - z[:, 2] * r[:, 1]  # z_{i-1} × (p - o_{i-1}), written out (np.cross is slow)
    J[1] = z[:, 2] * r[:, 0] - z[:, 0] * r[:, 2]
    J[2] = z[:, 0] * r[:, 1] - z[:, 1] * r[:, 0]
    J[3:] = z.T
    return J


# --------------------------------------------------------------------------------------------
# differential inverse kinematics


def dls_step(q, twist, damping: float = 0.05, *, T_flange_tool: np.ndarray | None = None,
             k_null: float = 0.0, q_home: np.ndarray = HOME_Q, free: np.ndarray | None = None) -> np.ndarray:
    """Damped-least-squares joint step for a base-frame twist (differential IK).

        dq = J_s^T (J_s J_s^T + lambda^2 I)^-1 S · twist  +  (I - J_s^+ J_s) · k_null · (q_home - q)

    `twist` = [v; omega] of the flange origin (or the tool origin) in the BASE frame, either a
    velocity (mm/s, rad/s -> dq in rad/s) or a small displacement (mm, rad -> dq in rad).
    S = diag(1/LENGTH_REF_MM x3, 1 x3) puts mm and rad on one scale, J_s = S·J; `damping` is
    lambda in those scaled units (0 = plain pseudo-inverse; ~0.01-0.1 keeps steps bounded near
    singularities).

    Redundancy (the 7th joint): the second term pulls q toward `q_home` (default HOME_Q, a bent,
    non-singular posture) inside the null space of the task, so it does not disturb the twist to
    first order. k_null has units 1/s for a velocity twist, or is a fraction for a displacement.

    `free` (bool, 7): joints marked False are held (zero column, zero dq), e.g. joints sitting at
    a range limit.
    """
    q = _q(q)
    J = jacobian(q, T_flange_tool)
    J[:3] /= LENGTH_REF_MM
    e = np.asarray(twist, dtype=float).copy()
    e[:3] /= LENGTH_REF_MM
    if free is not None:
        J[:, ~np.asarray(free, dtype=bool)] = 0.0
    JJt = J @ J.T + (damping * damping) * np.eye(6)
    dq = J.T @ np.linalg.solve(JJt, e)
    if k_null:
        # I - J^+ J as I - J^T (J J^T + eps I)^-1 J: the same projector for a full-rank J, bounded
        # near a singularity, and a 6x6 solve instead of an SVD
        N = np.eye(N_JOINTS) - J.T @ np.linalg.solve(J @ J.T + 1e-10 * np.eye(6), J)
        z = k_null * (np.asarray(q_home, dtype=float) - q)
        if free is not None:
            z[~np.asarray(free, dtype=bool)] = 0.0
        dq = dq + N @ z
    if free is not None:
        dq[~np.asarray(free, dtype=bool)] = 0.0
    return dq


class IKError(ValueError):
    """`ik` did not reach the target pose within tolerance (unreachable, or outside the joint
    ranges from this start)."""


def nearest_equivalent(q, q_ref, limits: PA10Limits) -> np.ndarray:
    """Per joint, the angle q_j + 2·pi·k inside [q_min_j, q_max_j] closest to q_ref_j.

    Only joints whose range spans more than a turn have a choice (E2 and W2, +-255 deg); for the
    others, and for a q_j with no equivalent in range, q_j is returned unchanged."""
    q, q_ref = _q(q), _q(q_ref)
    out = q.copy()
    k0 = np.round((q_ref - q) / (2 * np.pi))
    best = np.full(N_JOINTS, np.inf)
    for dk in (-1.0, 0.0, 1.0):
        cand = q + 2 * np.pi * (k0 + dk)
        ok = (cand >= limits.q_min) & (cand <= limits.q_max)
        dist = np.abs(cand - q_ref)
        take = ok & (dist < best)
        out[take] = cand[take]
        best[take] = dist[take]
    return out


def ik(T_target: np.ndarray, q0, limits: PA10Limits, *, T_flange_tool: np.ndarray | None = None,
       tol_mm: float = 0.05, tol_rad: float = 1e-4, max_iter: int = 300, damping: float = 0.02,
       k_null: float = 0.2, max_step_rad: float = 0.2, retry_from_home: bool = True) -> np.ndarray:
    """Iterative inverse kinematics: q (rad) with fk(q, T_flange_tool) = T_target (base frame, mm).

    Repeats q <- clip(q + dls_step(q, pose_error(T_target, fk(q)))) from q0, each step at most
    max_step_rad per joint, holding a joint that would leave its range at the limit (the step is
    re-solved without it). The redundant joint pulls toward HOME_Q (k_null). When the start q0
    fails and `retry_from_home`, it tries again from HOME_Q and from HOME_Q with S1 turned toward
    the target. The result is mapped to the
    equivalent angles nearest q0 (`nearest_equivalent`) and always lies inside the joint ranges.
    Raises IKError with the residual when the pose is not reached within tol_mm / tol_rad.
    """
    q0 = _q(q0)
    seeds = [np.clip(q0, limits.q_min, limits.q_max)]
    if retry_from_home:
        # HOME_Q, and HOME_Q turned by S1 to face the target (a pose behind the base is far
        # from HOME_Q in joint space and the DLS iteration stalls against a range end)
        p = T_target[:3, 3]
        facing = np.array(HOME_Q)
        facing[0] = np.clip(math.atan2(p[1], p[0]), limits.q_min[0], limits.q_max[0])
        seeds += [np.array(HOME_Q), facing]
    best = (np.inf, np.inf)
    for q in seeds:
        for _ in range(max_iter):
            e = pose_error(T_target, fk(q, T_flange_tool))
            ep, eo = float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:]))
            if ep <= tol_mm and eo <= tol_rad:
                return nearest_equivalent(q, q0, limits)
            free = np.ones(N_JOINTS, dtype=bool)
            for _ in range(3):
                dq = dls_step(q, e, damping, T_flange_tool=T_flange_tool, k_null=k_null, free=free)
                m = float(np.max(np.abs(dq)))
                if m > max_step_rad:
                    dq *= max_step_rad / m
                q_new = q + dq
                over = ((q_new < limits.q_min) | (q_new > limits.q_max)) & free
                if not over.any():
                    break
                free &= ~over
            q = np.clip(q_new, limits.q_min, limits.q_max)
        if ep + LENGTH_REF_MM * eo < best[0] + LENGTH_REF_MM * best[1]:
            best = (ep, eo)
    raise IKError(f"inverse kinematics did not converge: residual {best[0]:.3f} mm, "
                  f"{math.degrees(best[1]):.4f} deg (target unreachable within the joint ranges?)")


#: the links' capsule axes run between these frame origins (fk_frames indices): shoulder (2) ->
#: elbow (3) is the upper arm, elbow (4, same origin) -> wrist (5) the forearm, wrist (6) ->
#: flange (7) the wrist; frames 1/2, 3/4 and 5/6 share origins (a = 0, d_2 = d_4 = d_6 = 0)
CAPSULE_ENDS = (2, 3, 5, 7)


def link_capsules(frames: np.ndarray) -> np.ndarray:
    """The capsule end points (..., 4, 3) (mm, base frame) — shoulder, elbow, wrist, flange —
    from `fk_frames` output (..., 8, 4, 4): consecutive ends bound the upper arm, the forearm
    and the wrist (radii: [motion] link_radii_mm, servo/keepout.py)."""
    return frames[..., :3, 3][..., list(CAPSULE_ENDS), :]
