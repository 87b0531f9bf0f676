"""The photo-model (method step 1-2): from one photo of the kind of creature, the target region
by hue, and sampling points laid at a fixed pixel interval — *inner* points on the target, each
carrying its hue, and *outer* points in a band around it.

Frame: a model point at pixel offset (u, v) from the model origin (the centre of the target's
bounding rectangle in the photo; u along columns, v along rows) sits at (u/alpha, v/alpha, 0) mm
in the model frame, where alpha is the photo's unknown pixel-per-metric ratio (px/mm).

Hue is OpenCV's 8-bit hue, 0..179 (2 degrees per step), circular.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from photoservo.errors import InputError

HUE_BINS = 180
NO_HUE = 255  # marks a pixel too grey or too dark to carry a hue


@dataclass(frozen=True)
class PhotoModelParams:
    """[photo_model] config: how the model is cut out of the photo and sampled."""

    interval_px: float  # sampling interval of inner and outer points in the photo (px)
    band_px: float  # width of the outer band around the target (px)
    hue_tolerance: int  # hue distance (0..90) that still counts as "the same hue"
    min_saturation: int  # 0..255: below this a pixel carries no hue
    min_value: int  # 0..255: below this a pixel carries no hue
    max_points: int  # cap on inner + outer points (a coarser grid is used above it)


@dataclass(frozen=True)
class PhotoModel:
    """The 2-D pixel photo-model.

    inner_uv: (N_in, 2) float64 px offsets of inner points from the model origin (S_in).
    inner_hue: (N_in,) uint8 hue of each inner point (0..179).
    outer_uv: (N_out, 2) float64 px offsets of outer points (S_out).
    target_hues: (180,) bool, hues that belong to the target (inner hues widened by the
        tolerance); an outer point scores when the image hue there is *not* one of these.
    size_px: (width, height) of the target's bounding rectangle in the photo (px).
    origin_px: (x, y) of the model origin in the photo (px).
    mask: (H, W) uint8 target mask over the photo (255 = target), for previews.
    """

    inner_uv: np.ndarray
    inner_hue: np.ndarray
    outer_uv: np.ndarray
    target_hues: np.ndarray
    size_px: tuple[float, float]
    origin_px: tuple[float, float]
    mask: np.ndarray

    def size_mm(self, alpha: float) -> tuple[float, float]:
        """Real size (width along model x, height along model y) in mm at ratio alpha (px/mm)."""
        return (self.size_px[0] / alpha, self.size_px[1] / alpha)

    def points_mm(self, alpha: float) -> tuple[np.ndarray, np.ndarray]:
        """Inner and outer points as 3-D model-frame points (mm), z = 0: eq. of method step 2."""
        def lift(uv: np.ndarray) -> np.ndarray:
            return np.column_stack([uv / alpha, np.zeros(len(uv))])
        return lift(self.inner_uv), lift(self.outer_uv)


def hue_image(bgr: np.ndarray, min_saturation: int, min_value: int) -> np.ndarray:
    """OpenCV hue (0..179) of a BGR image; pixels below the saturation or value floor get NO_HUE."""
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    h = hsv[..., 0].copy()
    h[(hsv[..., 1] < min_saturation) | (hsv[..., 2] < min_value)] = NO_HUE
    return h


def hue_distance(a: np.ndarray | int, b: np.ndarray | int) -> np.ndarray:
    """Circular distance between OpenCV hues (0..90)."""
    d = np.abs(np.asarray(a, dtype=np.int16) - np.asarray(b, dtype=np.int16)) % HUE_BINS
    return np.minimum(d, HUE_BINS - d)
