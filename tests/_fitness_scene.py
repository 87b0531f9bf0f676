"""A tiny hand-built photo-model and a stereo pair rendered with cv2.warpPerspective, so the
fitness and scan tests do not depend on photo-model extraction or the synthetic renderer.

The photo: a two-coloured ellipse (orange head half, yellow-green tail half) on white (no hue).
The scene: that photo lying flat at pose (R, t, alpha) in front of the default rig, over blue
water. The plane-to-image map is the homography H = K · [r1/alpha, r2/alpha, t - (r1·ox + r2·oy)/alpha].
"""

from __future__ import annotations

import cv2
import numpy as np

from photoservo.vision.photo_model import HUE_BINS, PhotoModel, hue_distance, hue_image
from photoservo.vision.rig import Camera, Rig

ORANGE = (0, 100, 255)  # hue 12
GREEN = (40, 220, 200)  # hue 33
WATER = (170, 120, 40)  # hue 102


def make_photo(width: int = 160, height: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """(photo BGR, mask 0/255) of the two-coloured ellipse."""
    photo = np.full((height, width, 3), 255, np.uint8)
    mask = np.zeros((height, width), np.uint8)
    centre, axes = (width // 2, height // 2), (width // 2 - 20, height // 2 - 15)
    cv2.ellipse(mask, centre, axes, 0, 0, 360, 255, -1)
    photo[mask > 0] = ORANGE
    right = mask.copy()
    right[:, : width // 2 + 10] = 0
    photo[right > 0] = GREEN
    return photo, mask


def make_model(interval: int = 4, band: int = 12, tol: int = 10) -> tuple[PhotoModel, np.ndarray]:
    """A photo-model of `make_photo` by a plain grid: inner points inside the mask carrying the
    photo's hue, outer points in a band of `band` px around it. Returns (model, photo)."""
    photo, mask = make_photo()
    x, y, w, h = cv2.boundingRect(mask)
    origin = (x + (w - 1) / 2.0, y + (h - 1) / 2.0)
    hue = hue_image(photo, 60, 40)
    ring = cv2.dilate(mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * band + 1, 2 * band + 1)))
    ring[mask > 0] = 0
    ys, xs = np.mgrid[0 : photo.shape[0] : interval, 0 : photo.shape[1] : interval]
    xs, ys = xs.ravel(), ys.ravel()
    inner = mask[ys, xs] > 0
    outer = ring[ys, xs] > 0
    inner_hue = hue[ys[inner], xs[inner]].astype(np.uint8)
    target = np.zeros(HUE_BINS, bool)
    for hh in np.unique(inner_hue):
        target |= hue_distance(np.arange(HUE_BINS), int(hh)) <= tol
    model = PhotoModel(
        inner_uv=np.column_stack([xs[inner] - origin[0], ys[inner] - origin[1]]).astype(np.float64),
        inner_hue=inner_hue,
        outer_uv=np.column_stack([xs[outer] - origin[0], ys[outer] - origin[1]]).astype(np.float64),
        target_hues=target,
        size_px=(float(w), float(h)),
        origin_px=origin,
        mask=mask,
    )
    return model, photo


def rot(axis: str, deg: float) -> np.ndarray:
    """Rotation about a camera axis 'x', 'y' or 'z' by `deg` degrees."""
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def render_view(photo: np.ndarray, model: PhotoModel, cam: Camera, R: np.ndarray, t: np.ndarray,
                alpha: float, water=WATER) -> np.ndarray:
    """What camera `cam` sees of the photo's target at pose (R, t) in THAT camera's frame."""
    ox, oy = model.origin_px
    A = np.column_stack([R[:, 0] / alpha, R[:, 1] / alpha, t - (R[:, 0] * ox + R[:, 1] * oy) / alpha])
    H = cam.K @ A
    size = (cam.width, cam.height)
    img = np.empty((cam.height, cam.width, 3), np.uint8)
    img[:] = water
    warped = cv2.warpPerspective(photo, H, size, flags=cv2.INTER_LINEAR)
    m = cv2.warpPerspective(model.mask, H, size, flags=cv2.INTER_NEAREST)
    img[m > 0] = warped[m > 0]
    return img


def render_stereo(photo: np.ndarray, model: PhotoModel, rig: Rig, R: np.ndarray, t: np.ndarray,
                  alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """(left BGR, right BGR) of the target at pose (R, t) in the left camera frame."""
    left = render_view(photo, model, rig.left, R, t, alpha)
    right = render_view(photo, model, rig.right, rig.R @ R, rig.R @ t + rig.T, alpha)
    return left, right


# The truth used by the tests: facing the camera with a small tilt, 600 mm ahead, 1 px/mm.
R_TRUE = rot("z", 20) @ rot("x", 15)
T_TRUE = np.array([30.0, -20.0, 600.0])
ALPHA_TRUE = 1.0
