"""Sampling images at sub-pixel points: the grey and brightness planes and bilinear patches.

Shared by the photo-model (each inner point's grey and brightness in the photo,
`PhotoModel.inner_value` / `inner_brightness`), the appearance cue (`vision/appearance.py`: the
image's grey at the projected inner points) and the stereo plane fit (`vision/stereo_plane.py`:
grey patches matched along lines of sight). Pure: arrays in, arrays out; points are image or
photo pixels (x right, y down), images (H, W) float32.
"""

from __future__ import annotations

import math

import cv2
import numpy as np


def grey(bgr: np.ndarray) -> np.ndarray:
    """float32 grey image of a BGR image (`fit_target_plane`, `appearance`)."""
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)


def brightness(bgr: np.ndarray) -> np.ndarray:
    """float32 brightness V = max(B, G, R) of a BGR image (HSV's value)."""
    b, g, r = cv2.split(bgr)
    return cv2.max(cv2.max(b, g), r).astype(np.float32)


def saturation(bgr: np.ndarray) -> np.ndarray:
    """float32 saturation S = 255 (max - min) / max of a BGR image (HSV's saturation, OpenCV 8-bit scale):
    how pure its colour is, whatever its brightness (a gain of the light leaves it as it is)."""
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)[..., 1].astype(np.float32)


def patches(img: np.ndarray, uv: np.ndarray, half: int) -> tuple[np.ndarray, np.ndarray]:
    """Bilinearly sampled grey patches (..., k, k), k = 2 half + 1, centred on sub-pixel positions
    uv (..., 2); `ok` where the whole patch lies inside the image."""
    H, W = img.shape
    uv = np.nan_to_num(np.asarray(uv, dtype=np.float64), nan=-1e6)
    ok = (uv[..., 0] >= half) & (uv[..., 0] <= W - 1 - half) & (uv[..., 1] >= half) & (uv[..., 1] <= H - 1 - half)
    d = np.arange(-half, half + 1, dtype=np.float64)
    mx = (uv[..., 0][..., None, None] + d[None, :]).astype(np.float32)
    my = (uv[..., 1][..., None, None] + d[:, None]).astype(np.float32)
    mx, my = np.broadcast_arrays(mx, my)
    shape, n = mx.shape, mx.size
    cols = 4096  # cv2.remap wants maps narrower than 32767: lay the samples out in rows
    pad = (-n) % cols
    fx = np.concatenate([mx.ravel(), np.zeros(pad, np.float32)]).reshape(-1, cols)
    fy = np.concatenate([my.ravel(), np.zeros(pad, np.float32)]).reshape(-1, cols)
    out = cv2.remap(img, fx, fy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out.ravel()[:n].reshape(shape), ok


def sampling_pitch(uv: np.ndarray) -> float:
    """The grid pitch (px) of the photo-model's points (`photo_model._grid`): the smallest gap
    between distinct column offsets of the inner points (1.0 when the points are not a grid)."""
    x = np.unique(np.round(np.asarray(uv, dtype=np.float64)[:, 0], 3))
    gaps = np.diff(x)
    return float(gaps.min()) if gaps.size else 1.0


def photo_values(photo_bgr: np.ndarray, points_px: np.ndarray, pitch_px: float, plane=grey) -> np.ndarray:
    """`PhotoModel.inner_value`: the photo's grey level at each inner point (photo px), from the
    photo blurred by a Gaussian of sigma half a sampling pitch (each point stands for its cell of
    the grid, not for one pixel); `plane` = `brightness`: `PhotoModel.inner_brightness`. float32 (N,)."""
    return plane_values(plane(photo_bgr), points_px, pitch_px)


def plane_values(plane_img: np.ndarray, points_px: np.ndarray, pitch_px: float) -> np.ndarray:
    """`photo_values` from a plane of the photo already computed (float32 (H, W): `grey`, `brightness`,
    `saturation` or its equal from the photo's HSV, `photo_model.build_photo_model`). float32 (N,)."""
    g = cv2.GaussianBlur(plane_img, (0, 0), max(0.5, 0.5 * pitch_px))
    return patches(g, np.asarray(points_px, dtype=np.float64), 0)[0][:, 0, 0].astype(np.float32)


def image_values(uv: np.ndarray, image: np.ndarray, sigma_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The value of a float32 plane `image` (grey or brightness; bilinear) at image points uv (N, 2) px, blurred by a Gaussian of
    sigma `sigma_px` (only the box around the points is blurred). Returns (values (N,), inside (N,))."""
    H, W = image.shape
    ok = np.isfinite(uv).all(axis=1)
    ok &= (uv[:, 0] >= 0) & (uv[:, 0] <= W - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= H - 1)
    vals = np.zeros(len(uv), np.float64)
    if not ok.any():
        return vals, ok
    m = int(math.ceil(3 * sigma_px)) + 2
    x0, y0 = (max(0, int(np.floor(uv[ok, k].min())) - m) for k in (0, 1))
    x1, y1 = min(W, int(np.ceil(uv[ok, 0].max())) + m + 1), min(H, int(np.ceil(uv[ok, 1].max())) + m + 1)
    roi = np.ascontiguousarray(image[y0:y1, x0:x1], dtype=np.float32)
    if sigma_px >= 0.3:
        roi = cv2.GaussianBlur(roi, (0, 0), sigma_px)
    p, inside = patches(roi, uv[ok] - (x0, y0), 0)
    vals[ok] = p[:, 0, 0]
    ok[ok] = inside
    return vals, ok
