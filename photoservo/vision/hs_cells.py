"""The photo's colours as cells of (hue, saturation), OpenCV 8-bit HSV: the photo's table of cells
(`photo_cells`) and an image's pixels on them (`cell_image`). What they are for and what they were
measured to tell: vision/colour_cells.py. Apart from it because the photo-model builds its table
(`photo_model.build_photo_model`) and colour_cells reads the fitness, which reads the photo-model:
this module needs OpenCV only."""

from __future__ import annotations

import cv2
import numpy as np

CELL_HUES = 12  # OpenCV hues (0..179) per cell: 15 hue levels
CELL_SATURATIONS = 32  # saturation levels (0..255) per cell: 8 levels
CELL_MIN_SATURATION = 12  # below this a pixel is grey for the cells (the fitness' own floor is 60)
CELL_SHARE = 0.02  # a cell is the photo's when it holds at least this share of the target's pixels


def _cell_index(hsv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return hsv[..., 0] // CELL_HUES, hsv[..., 1] // CELL_SATURATIONS


def photo_cells(photo_bgr: np.ndarray, mask: np.ndarray, min_value: int, hsv: np.ndarray | None = None) -> np.ndarray:
    """(180 / CELL_HUES, 256 / CELL_SATURATIONS) bool: the cells holding >= CELL_SHARE of the target's
    pixels (`mask` > 0) with saturation >= CELL_MIN_SATURATION and value >= `min_value`; all False
    when there are none. `hsv`: the photo in HSV when the caller has it (`build_photo_model`)."""
    hsv = cv2.cvtColor(photo_bgr, cv2.COLOR_BGR2HSV) if hsv is None else hsv
    sel = (mask > 0) & (hsv[..., 1] >= CELL_MIN_SATURATION) & (hsv[..., 2] >= min_value)
    table = np.zeros((-(-180 // CELL_HUES), -(-256 // CELL_SATURATIONS)))
    h, s = _cell_index(hsv[sel])
    np.add.at(table, (h, s), 1)
    return table >= CELL_SHARE * max(1, int(sel.sum())) if sel.any() else table > 0


def cell_image(bgr: np.ndarray, cells: np.ndarray, min_value: int) -> np.ndarray:
    """(H, W) bool: pixels of `bgr` on one of `cells` (`photo_cells`), above the cells' saturation floor
    and `min_value`."""
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    h, s = _cell_index(hsv)
    return cells[h, s] & (hsv[..., 1] >= CELL_MIN_SATURATION) & (hsv[..., 2] >= min_value)
