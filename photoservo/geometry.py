"""The one home for the maths of frames: 4x4 pose builders T_a_b, rotations about an axis,
rotation log / angle / mean, the pose error of the servo law and IK, and the orientation of the
flat photo-model as heading and tilt (the GA's three orientation genes).

Poses are 4x4 homogeneous transforms named by their frames, T_a_b with X_a = T_a_b · X_b
(millimetres); rotations are 3x3 matrices, angles in radians unless a name says _deg.

A pose is "model in left-camera frame" (DESIGN.md): X_left = R · X_model + t. The model is flat
(z_model = 0); its normal is R[:, 2]. We write

    R = R_tilt(tilt_x, tilt_y) · Rz(psi)

* psi (heading): the turn of the model about its own normal, radians, any value;
* (tilt_x, tilt_y): a rotation vector perpendicular to the camera's optical axis that tips the
  model's normal away from the camera's z axis; its length is the tilt angle
  (tilt = angle between R[:, 2] and the optical axis), radians.

R = I (psi = 0, no tilt) is the model facing the left camera as photographed. Tilt is weakly
observable for a flat target, heading strongly: the two errors are reported separately by
`heading_tilt_error` (a swing-twist split of the error rotation about the model normal).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def rotation_from_heading_tilt(psi: np.ndarray, tilt_x: np.ndarray, tilt_y: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations R = R_tilt(tilt_x, tilt_y) · Rz(psi); angles in radians.

    >>> np.allclose(rotation_from_heading_tilt(0.0, 0.0, 0.0), np.eye(3))
    True
    """
    psi, tx, ty = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (psi, tilt_x, tilt_y)))
    th = np.hypot(tx, ty)
    small = th < 1e-12
    inv = 1.0 / np.where(small, 1.0, th)
    kx = np.where(small, 1.0, tx * inv)
    ky = np.where(small, 0.0, ty * inv)
    s, c = np.sin(th), np.cos(th)
    v = 1.0 - c
    cp, sp = np.cos(psi), np.sin(psi)
    # R_tilt (Rodrigues with axis k = (kx, ky, 0)) times Rz(psi), multiplied out
    a00, a01, a02 = c + kx * kx * v, kx * ky * v, ky * s
    a10, a11, a12 = kx * ky * v, c + ky * ky * v, -kx * s
    a20, a21, a22 = -ky * s, kx * s, c
    R = np.empty(th.shape + (3, 3))
    R[..., 0, 0] = a00 * cp + a01 * sp
    R[..., 0, 1] = a01 * cp - a00 * sp
    R[..., 0, 2] = a02
    R[..., 1, 0] = a10 * cp + a11 * sp
    R[..., 1, 1] = a11 * cp - a10 * sp
    R[..., 1, 2] = a12
    R[..., 2, 0] = a20 * cp + a21 * sp
    R[..., 2, 1] = a21 * cp - a20 * sp
    R[..., 2, 2] = a22
    return R


def heading_tilt_from_rotation(R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of `rotation_from_heading_tilt`: (psi, tilt_x, tilt_y), radians, psi in (-pi, pi].
    Defined for tilts below 180 degrees."""
    R = np.asarray(R, dtype=np.float64)
    n = R[..., :, 2]
    th = np.arctan2(np.hypot(n[..., 0], n[..., 1]), n[..., 2])
    # axis = e_z x n = (-n_y, n_x, 0), normalised
    ax, ay = -n[..., 1], n[..., 0]
    norm = np.hypot(ax, ay)
    safe = np.where(norm > 1e-12, norm, 1.0)
    tx = np.where(norm > 1e-12, ax / safe * th, 0.0)
    ty = np.where(norm > 1e-12, ay / safe * th, 0.0)
    Rt = rotation_from_heading_tilt(np.zeros_like(th), tx, ty)
    Rz = np.swapaxes(Rt, -1, -2) @ R
    psi = np.arctan2(Rz[..., 1, 0], Rz[..., 0, 0])
    return psi, tx, ty


def tilt_angle(R: np.ndarray) -> np.ndarray:
    """Angle (rad) between the model normal R[:, 2] and the camera's optical axis."""
    R = np.asarray(R)
    return np.arctan2(np.hypot(R[..., 0, 2], R[..., 1, 2]), R[..., 2, 2])


def heading_tilt_error(R_true: np.ndarray, R_est: np.ndarray) -> tuple[float, float]:
    """(heading error, tilt error) in degrees between two model orientations.

    Tilt error: angle between the two model normals. Heading error: the twist left about the
    normal once the normals are aligned (swing-twist split of R_true^T R_est)."""
    R_true = np.asarray(R_true, dtype=np.float64)
    R_est = np.asarray(R_est, dtype=np.float64)
    tilt = np.arctan2(np.linalg.norm(np.cross(R_true[:, 2], R_est[:, 2])), R_true[:, 2] @ R_est[:, 2])
    E = R_true.T @ R_est
    psi, _, _ = heading_tilt_from_rotation(E)
    return float(np.degrees(abs(psi))), float(np.degrees(tilt))


# ----------------------------------------------------------------------------- poses


def make_pose(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform T with X_a = R · X_b + t, i.e. T_a_b from R (3x3) and t (3,),
    mm. Also attaches a tool (T_flange_tool) or a hand-eye (T_flange_camera) to the flange.

    >>> make_pose(np.eye(3), [1.0, 2.0, 3.0]) @ [0.0, 0.0, 0.0, 1.0]
    array([1., 2., 3., 1.])
    """
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(t, dtype=np.float64).ravel()
    return T


def invert_pose(T: np.ndarray) -> np.ndarray:
    """T_b_a from T_a_b for a rigid transform: [R^T, -R^T t].

    >>> T = make_pose(axis_rotation(2, 0.3), [10.0, -5.0, 2.0])
    >>> bool(np.allclose(invert_pose(T) @ T, np.eye(4)))
    True
    """
    R, t = T[:3, :3], T[:3, 3]
    return make_pose(R.T, -R.T @ t)


def pose_error(T_target: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Pose error e = [p* - p (mm); w] (6,), both in the frame the poses are given in (the arm's
    BASE frame for the servo law and IK), where w is the rotation vector of R* · R^T: the twist
    that, applied for unit time at T's origin, reaches T*."""
    e = np.empty(6)
    e[:3] = T_target[:3, 3] - T[:3, 3]
    e[3:] = rotation_log(T_target[:3, :3] @ T[:3, :3].T)
    return e


# ----------------------------------------------------------------------------- rotations


def axis_rotation(axis: int, angle: float) -> np.ndarray:
    """Rotation by `angle` (rad, right-hand rule) about coordinate axis 0 (x), 1 (y) or 2 (z).

    >>> np.round(axis_rotation(2, math.pi / 2) @ [1.0, 0.0, 0.0], 12) + 0.0
    array([0., 1., 0.])
    """
    c, s = math.cos(angle), math.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def rotation_log(R: np.ndarray) -> np.ndarray:
    """Rotation vector w (axis · angle, rad) with R = exp([w]x), angle in [0, pi].

    >>> bool(np.allclose(rotation_log(axis_rotation(1, 0.5)), [0.0, 0.5, 0.0]))
    True
    """
    c = float(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))
    angle = math.acos(c)
    vee = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-6:
        return 0.5 * vee
    if angle < math.pi - 1e-4:
        return angle / (2.0 * math.sin(angle)) * vee
    # near pi: the axis from the symmetric part, (R + R^T)/2 = cos(angle) I + (1 - cos(angle)) n n^T
    B = ((R + R.T) / 2.0 - c * np.eye(3)) / (1.0 - c)
    k = int(np.argmax(np.diag(B)))
    n = B[:, k] / math.sqrt(B[k, k])
    if n @ vee < 0:
        n = -n
    return angle * n / np.linalg.norm(n)


def rotation_angle_deg(R: np.ndarray) -> float:
    """Angle of a rotation matrix (deg), 0..180."""
    return math.degrees(math.acos(float(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))))


def mean_rotation(Rs: Sequence[np.ndarray]) -> np.ndarray:
    """Chordal L2 mean of rotations (the rotation nearest to their sum)."""
    U, _, Vt = np.linalg.svd(np.sum(Rs, axis=0))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt
