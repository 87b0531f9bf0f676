"""The look-alike twins of a flat creature's pose (method step 4's ambiguity check): poses the hue
fitness confuses with the true one. `alternatives`: the planar-pose mirror and the heading turned
by 180 degrees about the model origin (`PoseSearch.twin_steps`); `turned_about_centroid`: the
head-to-tail twin at the same place, turned about the photo mask's centroid, which the hue
fitness scores alike and the appearance cue (`vision/appearance.py`) can tell apart; with
`quarters` = +-1 the pose turned a quarter about that centroid (`candidates.quarter_twins`: an oblong
target inside a region of its hues, fitted across it).

Frames: R, t model in the left camera frame (mm); alpha px/mm.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from photoservo.vision.photo_model import PhotoModel


def alternatives(R: np.ndarray, t: np.ndarray) -> list[np.ndarray]:
    """Orientations a flat target's pose is easily confused with (see `PoseSearch.run`): the
    planar-ambiguity mirror, the heading turned by 180 degrees about the model normal, and both."""
    half_turn = np.diag([-1.0, -1.0, 1.0])  # Rz(pi): heading + 180 deg
    R_m = reflected_rotation(R, t)
    return [R_m, R @ half_turn, R_m @ half_turn]


def reflected_rotation(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The other solution of the planar pose ambiguity: a flat target seen along the ray d = t/|t|
    looks nearly alike with its normal n and with n' = 2 (n·d) d - n (the normal mirrored about
    the line of sight). Returns R' = Rot(n -> n') · R, the smallest turn taking n to n'."""
    d = np.asarray(t, dtype=np.float64) / np.linalg.norm(t)
    n = R[:, 2]
    n2 = 2.0 * (n @ d) * d - n
    axis = np.cross(n, n2)
    s = np.linalg.norm(axis)
    if s < 1e-12:
        return R.copy()
    ang = math.atan2(s, float(n @ n2))
    rvec = axis / s * ang
    return cv2.Rodrigues(rvec)[0] @ R


def mask_centroid_mm(model: PhotoModel, alpha: float) -> np.ndarray:
    """The photo mask's centroid in the model frame (mm, z = 0) at ratio alpha (px/mm)."""
    m = cv2.moments(model.mask, binaryImage=True)
    if m["m00"] <= 0:
        return np.zeros(3)
    return np.array([(m["m10"] / m["m00"] - model.origin_px[0]) / alpha,
                     (m["m01"] / m["m00"] - model.origin_px[1]) / alpha, 0.0])


def turned_about_centroid(R: np.ndarray, t: np.ndarray, alpha: float, model: PhotoModel, aspect: float = 1.0,
                          quarters: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """The head-to-tail twin of a pose: the model turned by 180 degrees about its normal through
    the photo mask's centroid (not the box centre: the creature stays where it lies). R (3, 3)
    rotation, t (3,) mm, alpha px/mm, `aspect` the per-axis k (`Candidate.aspect`). Returns
    (R', t') with R' = R · Rz(pi) and t' = t + 2 M c, M = R · diag(k, 1/k, 1) and c the centroid
    (`mask_centroid_mm`), so that the centroid stays put: M' c + t' = M c + t. `quarters`: turned by
    that many quarter turns instead (1: +90 degrees, -1: -90 degrees; `quarter_twins`).

    >>> from types import SimpleNamespace
    >>> m = SimpleNamespace(mask=np.pad(np.ones((2, 4), np.uint8), ((0, 0), (0, 4))), origin_px=(0.0, 0.0))
    >>> R2, t2 = turned_about_centroid(np.eye(3), np.zeros(3), 1.0, m, quarters=1)
    >>> c = mask_centroid_mm(m, 1.0); bool(np.allclose(R2 @ c + t2, c)), R2[:2, 0].round(6).tolist()
    (True, [0.0, 1.0])
    """
    R = np.asarray(R, dtype=np.float64)
    c = mask_centroid_mm(model, alpha) * np.array([aspect, 1.0 / aspect, 0.0])
    Rz = np.linalg.matrix_power(np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), quarters % 4)
    R2 = R @ Rz
    return R2, np.asarray(t, dtype=np.float64) + (R @ c - R2 @ c)
