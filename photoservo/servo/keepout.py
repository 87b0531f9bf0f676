"""Cartesian keep-out by volumes, checked continuously along a motion (issue 12; part of the
safety layer of method step 6, servo/motion.py).

The arm is kept above the water plane (`z_min_mm`) and inside the workspace box as VOLUMES:

- capsules around the links (robot/pa10.py `link_capsules`): upper arm, forearm, wrist, each a
  segment between joint origins with a radius ([motion] link_radii_mm); the upper arm's
  shoulder end does not move (it is part of the base: no motion can change its clearance), so
  its elbow end decides;
- a box around the camera rig and the tool, fixed to the flange ([motion] rig_box_min_mm /
  rig_box_max_mm, flange frame), and the tool point itself.

Every boundary is a half-space and every volume is convex, so a capsule is inside when both
ends are at least its radius inside, and the box when its 8 corners are: the CLEARANCE of a
configuration is the least of those signed distances (mm, negative = a volume crosses).

Along a motion q(t) the clearance is checked continuously, not at samples: with every joint
speed bounded by v (rad/s), no point of a volume moves faster than V = sum_j v_j · R_j, R_j the
reach beyond joint j (a = 0 for the PA-10, so R_j = d_j + ... + d_7 + the farthest box corner).
Between two samples h apart with clearances c_a, c_b >= 0 the clearance stays >= 0 when
c_a + c_b >= h · V (each point is within the speed bound of both ends); an interval that fails
this is halved until it passes, a midpoint crosses, or it is shorter than MIN_STEP_S (then the
motion is refused: clearance not proven). A dip between samples is thus always caught.

Frames and units: base frame (z up) in mm, joints in rad, time in s. Pure: arrays in, text out.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from photoservo.robot.pa10 import DH_D_MM, fk_frames, link_capsules
from photoservo.servo.braking import stopping_speed

#: `Keepout.features`' rows: the moving capsule ends, the rig box corners, the tool point (last,
#: as servo/motion.py's tool-speed cap reads it)
FEATURES = ("elbow", "wrist", "flange", *(f"camera rig box corner {i + 1}" for i in range(8)), "tool")
_MOVED_BY = np.array([3, 5, 7, *(7,) * 8, 7])  # joints 1..n move each feature
MIN_STEP_S = 1e-4  # shortest interval the continuous check halves down to (s)


class Keepout:
    """The arm's keep-out volumes against the water plane and the workspace box.

    Args:
        z_min_mm: the water plane + clearance (base frame z, mm).
        box_min_mm, box_max_mm: the workspace box (base frame, mm).
        link_radii_mm: capsule radii of the upper arm, forearm and wrist (mm).
        rig_box_min_mm, rig_box_max_mm: the camera rig + tool box in the flange frame (mm).
        T_flange_tool: the tool point (4x4, flange frame, mm).
    """

    def __init__(self, z_min_mm: float, box_min_mm, box_max_mm, link_radii_mm, rig_box_min_mm,
                 rig_box_max_mm, T_flange_tool: np.ndarray) -> None:
        lo, hi = np.asarray(box_min_mm, float), np.asarray(box_max_mm, float)
        self.lo = np.array([lo[0], lo[1], max(z_min_mm, lo[2])])
        self.hi = hi
        self.z_min_mm = z_min_mm
        r = np.asarray(link_radii_mm, float)
        # capsule ends share radii: a shared end takes the larger one (conservative)
        self.radius = np.concatenate([[max(r[0], r[1]), max(r[1], r[2]), r[2]], np.zeros(9)])
        bmin, bmax = np.asarray(rig_box_min_mm, float), np.asarray(rig_box_max_mm, float)
        corners = np.array([[x, y, z] for x in (bmin[0], bmax[0]) for y in (bmin[1], bmax[1])
                            for z in (bmin[2], bmax[2])])
        self.corners_h = np.concatenate([corners, np.ones((8, 1))], axis=1)  # (8, 4), flange frame
        self.tool_h = np.asarray(T_flange_tool, float)[:, 3]
        far = max(float(np.max(np.linalg.norm(corners, axis=1))), float(np.linalg.norm(self.tool_h[:3])))
        # reach beyond joint j (mm): d_j + ... + d_7 + the farthest rig/tool point, plus the radius
        self.reach_mm = np.cumsum(DH_D_MM[::-1])[::-1] + far

    def features(self, Q: np.ndarray) -> np.ndarray:
        """Feature points (N, 12, 3) (mm, base frame) at configurations Q (N, 7), as FEATURES:
        the moving capsule ends (elbow, wrist, flange), the 8 rig box corners, the tool point."""
        return self.points(fk_frames(np.atleast_2d(Q)))

    def points(self, F: np.ndarray) -> np.ndarray:
        """`features` from the link frames F (N, 8, 4, 4) of `fk_frames`."""
        ends = link_capsules(F)[:, 1:]  # (N, 3, 3): the shoulder end is fixed
        flange = F[:, -1, :3]  # (N, 3, 4)
        tool = (flange @ self.tool_h)[:, None, :]
        corners = (flange @ self.corners_h.T).transpose(0, 2, 1)  # (N, 8, 3)
        return np.concatenate([ends, corners, tool], axis=1)

    def point_jacobians(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Feature points P (K, 3) (mm, base frame) and their translational Jacobians J (K, 3, 7)
        at q (7,): J_v,i = z_{i-1} x (p - o_{i-1}) for the joints that move the point."""
        F = fk_frames(q)
        z, o = F[:-1, :3, 2], F[:-1, :3, 3]
        P = self.points(F[None])[0]
        r = P[:, None, :] - o[None, :, :]  # (K, 7, 3)
        J = np.stack([z[:, 1] * r[..., 2] - z[:, 2] * r[..., 1],
                      z[:, 2] * r[..., 0] - z[:, 0] * r[..., 2],
                      z[:, 0] * r[..., 1] - z[:, 1] * r[..., 0]], axis=1)  # (K, 3, 7)
        J *= (np.arange(7)[None, :] < _MOVED_BY[:, None])[:, None, :]
        return P, J

    def clearance(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per configuration of Q (N, 7): the least clearance (N,) (mm), the feature index and
        the boundary index (0-2 lower x/y/z faces — z is the water — 3-5 upper faces)."""
        return self.clearance_of(self.features(Q))

    def clearance_of(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`clearance` from the feature points P (N, K, 3) (mm, base frame) of `features`."""
        d = np.concatenate([P - self.lo, self.hi - P], axis=2) - self.radius[None, :, None]  # (N, K, 6)
        flat = d.reshape(len(d), -1)
        i = np.argmin(flat, axis=1)
        return flat[np.arange(len(d)), i], i // 6, i % 6

    def describe(self, c: float, feature: int, face: int, t: float | None = None) -> str:
        """One line naming the volume and the boundary a clearance c (mm) < 0 crosses."""
        what = FEATURES[feature].split(" corner")[0]
        when = "" if t is None else f" at t = {t:.3f} s"
        if face == 2 and self.lo[2] == self.z_min_mm:
            return f"the {what} would go below the water plane ({-c:.1f} mm under z_min_mm = {self.z_min_mm:g}{when})"
        side = ("workspace_min_mm", "workspace_max_mm")[face // 3]
        return f"the {what} would leave the workspace box ({-c:.1f} mm past {side}[{face % 3}]{when})"

    def violation(self, Q: np.ndarray) -> str:
        """'' when every configuration of Q ((7,) or (N, 7)) keeps all volumes inside, else why."""
        c, f, b = self.clearance(Q)
        k = int(np.argmin(c))
        return "" if c[k] >= 0 else self.describe(float(c[k]), int(f[k]), int(b[k]))

    def approach_caps(self, P: np.ndarray, J: np.ndarray, dq: np.ndarray, lead_s: float, a_cart: float,
                      j_cart: float, margin_mm: float) -> tuple[np.ndarray, list[str]]:
        """Velocity-target filter (so the braking check rarely has to stop the arm): each feature
        (P (K, 3) mm, Jacobians J (K, 3, 7) from `point_jacobians`) approaching a boundary is
        capped at the speed from which it could stop, with a nominal Cartesian deceleration
        a_cart (mm/s²) and jerk j_cart (mm/s³), lead_s ahead and margin_mm inside the boundary,
        by scaling the whole joint velocity dq (rad/s) down (the arm slows along the commanded
        motion). Returns the scaled dq and the volumes that were slowed. Heuristic; the braking
        check (`sweep_violation`) is the guarantee."""
        V = J @ dq  # (K, 3) feature velocities (mm/s)
        approach = np.concatenate([-V, V], axis=1)  # toward the lower faces, toward the upper faces
        clearance = np.concatenate([P - self.lo, self.hi - P], axis=1) - self.radius[:, None] - margin_mm
        allow = stopping_speed(clearance - lead_s * np.maximum(approach, 0), a_cart, j_cart)
        over = approach > allow
        if not over.any():
            return dq, []
        scale = float(np.min(allow[over] / approach[over]))
        return dq * scale, list(dict.fromkeys(FEATURES[k].split(" corner")[0] for k in np.flatnonzero(over.any(axis=1))))

    def speed_bound(self, v_joint: np.ndarray) -> float:
        """Highest speed (mm/s) of any volume point with joint speeds |dq_j| <= v_joint (rad/s)."""
        return float(np.abs(v_joint) @ self.reach_mm)

    def sweep_violation(self, q_at: Callable[[float], np.ndarray], duration: float, v_joint: np.ndarray,
                        step_s: float = 0.02) -> str:
        """Continuous check of the motion q_at(t), 0 <= t <= duration, whose joint speeds stay
        within v_joint (rad/s): '' when the volumes provably stay inside, else the first
        crossing found (see the module docstring)."""
        n = max(1, int(np.ceil(duration / step_s)))
        ts = np.minimum(np.arange(n + 1) * step_s, duration)
        c, f, b = self.clearance(np.array([np.asarray(q_at(t), float) for t in ts]))
        k = int(np.argmin(c))
        if c[k] < 0:
            return self.describe(float(c[k]), int(f[k]), int(b[k]), float(ts[k]))
        V = self.speed_bound(v_joint)
        todo = [(ts[i], ts[i + 1], c[i], c[i + 1]) for i in range(n) if c[i] + c[i + 1] < (ts[i + 1] - ts[i]) * V]
        while todo:
            ta, tb, ca, cb = todo.pop()
            if tb - ta < MIN_STEP_S:
                return (f"clearance of the arm's volumes not proven near t = {ta:.3f} s "
                        f"({min(ca, cb):.2f} mm at {V:.0f} mm/s)")
            tm = 0.5 * (ta + tb)
            cm, fm, bm = self.clearance(np.asarray(q_at(tm), float)[None])
            if cm[0] < 0:
                return self.describe(float(cm[0]), int(fm[0]), int(bm[0]), tm)
            for a, bb, x, y in ((ta, tm, ca, cm[0]), (tm, tb, cm[0], cb)):
                if x + y < (bb - a) * V:
                    todo.append((a, bb, x, y))
        return ""
