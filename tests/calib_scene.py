"""A known stereo rig, board poses and flange poses, rendered through `BoardRenderer`: the ground
truth behind the calibration tests (imported by tests/test_calibrate*.py)."""

from __future__ import annotations

import cv2
import numpy as np

from photoservo.vision.board import Board, BoardRenderer, MarkerRenderer
from photoservo.vision.calibrate import make_T
from photoservo.vision.rig import Camera, Rig

SIZE = (480, 360)


def true_rig() -> Rig:
    """Two slightly different cameras with mild barrel distortion (k3 = 0), 100 mm apart, the
    right one rotated by about 2 degrees."""
    left = Camera(SIZE, np.array([[520.0, 0.0, 243.0], [0.0, 516.0, 176.0], [0.0, 0.0, 1.0]]),
                  np.array([-0.12, 0.06, 0.0008, -0.0006, 0.0]))
    right = Camera(SIZE, np.array([[531.0, 0.0, 236.0], [0.0, 528.0, 185.0], [0.0, 0.0, 1.0]]),
                   np.array([-0.10, 0.04, -0.0005, 0.0009, 0.0]))
    R = cv2.Rodrigues(np.radians([0.8, -1.6, 0.5]))[0]
    T = np.array([-100.0, 1.2, -2.5])
    return Rig(left, right, R, T)


def true_hand_eye() -> np.ndarray:
    """T_flange_left: the left camera 60 mm off the flange axis, 90 mm below the plate, turned
    about the flange z and tilted a little."""
    return make_T(cv2.Rodrigues(np.array([0.05, -0.08, 1.2]))[0], np.array([60.0, -25.0, 90.0]))


def stereo_board_poses(n: int, seed: int = 1) -> list[np.ndarray]:
    """n poses T_left_board of a 9x6 / 25 mm board, centred between the cameras, 450..650 mm
    away, tilted up to ~35 degrees about varied axes."""
    rng = np.random.default_rng(seed)
    board_c = np.array([125.0, 87.5, 0.0])  # centre of a 9x6 / 25 mm board in its frame
    poses = []
    for k in range(n):
        tilt = np.radians(rng.uniform(15, 35)) * np.array([np.cos(2.4 * k), np.sin(2.4 * k), 0.0])
        R = cv2.Rodrigues(tilt)[0] @ cv2.Rodrigues(np.array([0.0, 0.0, rng.uniform(-0.3, 0.3)]))[0]
        centre = np.array([50.0 + rng.uniform(-30, 30), rng.uniform(-25, 25), rng.uniform(450, 650)])
        poses.append(make_T(R, centre - R @ board_c))
    return poses


_RENDERERS: dict = {}


def renderer(board: Board, cam: Camera) -> BoardRenderer:
    """A BoardRenderer, cached per (board, camera) for the test session (the per-pixel rays
    are the slow part)."""
    key = (board, cam.size, cam.K.tobytes(), cam.dist.tobytes())
    if key not in _RENDERERS:
        _RENDERERS[key] = BoardRenderer(board, cam)
    return _RENDERERS[key]


def render_stereo(board: Board, rig: Rig, poses: list[np.ndarray], noise_sigma: float = 0.0,
                  seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """(left, right) BGR images of the board at each T_left_board."""
    rng = np.random.default_rng(seed)
    rl, rr = renderer(board, rig.left), renderer(board, rig.right)
    out = []
    for T in poses:
        Tr = make_T(rig.R, rig.T) @ T
        out.append((rl.render(T[:3, :3], T[:3, 3], rng=rng, noise_sigma=noise_sigma),
                    rr.render(Tr[:3, :3], Tr[:3, 3], rng=rng, noise_sigma=noise_sigma)))
    return out


def look_at_flange_poses(T_base_board: np.ndarray, T_flange_left: np.ndarray, n: int, seed: int = 3,
                         rotate: bool = True) -> list[np.ndarray]:
    """n flange poses T_base_flange from which the left camera sees the board: the camera
    ~500 mm from the board, looking at its centre, from directions tilted up to ~25 degrees
    about varied axes and rolled about its axis (or, with rotate=False, only translated)."""
    rng = np.random.default_rng(seed)
    centre = T_base_board @ np.array([125.0, 87.5, 0.0, 1.0])
    # a camera straight above the board looking down (its z = board's z, into the board)
    R0 = T_base_board[:3, :3]
    poses = []
    for k in range(n):
        if rotate:
            tilt = np.radians(rng.uniform(10, 25)) * np.array([np.cos(2.1 * k), np.sin(2.1 * k), 0.0])
            R_cam = R0 @ cv2.Rodrigues(tilt)[0] @ cv2.Rodrigues(np.array([0.0, 0.0, rng.uniform(-0.6, 0.6)]))[0]
        else:
            R_cam = R0
        dist = rng.uniform(450, 600)
        p_cam = centre[:3] - R_cam[:, 2] * dist + (R_cam[:, :2] @ rng.uniform(-25, 25, 2) if not rotate else 0)
        T_base_left = make_T(R_cam, p_cam)
        poses.append(T_base_left @ np.linalg.inv(T_flange_left))
    return poses


def render_markers(rig, T_base_left, markers, noise=1.0, seed=0):
    """Left and right images of single ArUco markers [(id, side_mm, T_base_marker)] floating in
    one view (composited), as BGR images."""
    rng = np.random.default_rng(seed)
    images = []
    for cam, T_cam_left in ((rig.left, np.eye(4)), (rig.right, make_T(rig.R, rig.T))):
        img = np.full((cam.size[1], cam.size[0], 3), 110, np.uint8)
        for marker_id, side, T_bm in markers:
            T = T_cam_left @ np.linalg.inv(T_base_left) @ T_bm
            img = MarkerRenderer("DICT_4X4_250", marker_id, side, cam).render(T[:3, :3], T[:3, 3], base=img)
        noisy = img.astype(float) + rng.normal(0, noise, img.shape)
        images.append(np.clip(np.rint(noisy), 0, 255).astype(np.uint8))
    return images
