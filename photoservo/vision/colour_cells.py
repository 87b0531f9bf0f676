"""The photo's colours over hue and saturation (issue 9's photo-model extension, used by detection).

Where the target's hues cover most of the pair (the contour rule's regime, `estimator.hues_everywhere`:
a plant before a patterned backdrop, a red motorcycle in a garage of wood) hue cannot tell the target
from any stuff of its colour, and a pale target barely carries hue at all (the aloe's leaves: saturation
median 57, under the [fitness] floor of 60; 38-56 % of their pixels read as no hue). The photo's
pixels, down to a low saturation floor, fall into a few cells of (hue, saturation): `CELL_HUES` hue
levels by `CELL_SATURATIONS` saturation levels (OpenCV 8-bit HSV), a cell kept when it holds at least
`CELL_SHARE` of the target's pixels (a density: a badge, a spine or a highlight does not count). The
pair's pixels whose (hue, saturation) lies in a kept cell are the photo's colours (`stereo_cells`);
`cell_share` is the share of a pose's inner points on them (the worse camera). They tell a place only
where they are a minority of the pair's pixels (`distinctive`). The table of cells and an image's pixels
on it are vision/hs_cells.py's (OpenCV only: the photo-model builds the table).

Measured on the real pairs at the true poses (scratch, seed 0): the leaves' inner points lie on the
photo's colours 0.85-0.90 against 0.51-0.59 for the same model's 90th percentile elsewhere (by hue
0.47-0.56 against 0.85-0.88: no separation); the pot 0.91-0.96 against 0.23-0.25, the motorcycle's
targets 0.76-0.98 against 0.42-0.73. The value (brightness) is left out: shading and highlights move
it, and detection compares the pair with itself (`detection.detect`, at placements elsewhere), not
with the photo's light."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from photoservo.vision.fitness import nearest_pixel, project_uv
from photoservo.vision.hs_cells import cell_image
from photoservo.vision.rig import Rig

# the cells tell a place only where the photo's colours are a minority of the pair: at most this share of
# either image's pixels (`distinctive`). The real pairs' photos 0.11-0.47; the harbour generator's
# many-hued fish whose colours are the water's 0.65-0.97 (1700, 1702, 1703), where the fish's own inner
# points, rendered, lie on them less often (0.60-0.64) than the water does (0.69-0.99 at the 0.9 quantile)
MAX_PAIR_SHARE = 0.5


@dataclass(frozen=True)
class StereoCells:
    """Per camera, (H, W) bool: the pixel's (hue, saturation) lies in one of the photo's cells."""

    left: np.ndarray
    right: np.ndarray


def stereo_cells(left_bgr: np.ndarray, right_bgr: np.ndarray, cells: np.ndarray, min_value: int) -> StereoCells:
    """The pair's pixels on the photo's colours (`cell_image`), both cameras."""
    return StereoCells(left=cell_image(left_bgr, cells, min_value), right=cell_image(right_bgr, cells, min_value))


def distinctive(cells: StereoCells) -> bool:
    """Are the photo's colours a minority of the pair (at most MAX_PAIR_SHARE of each image's pixels)?
    Where they are most of it, a pose on them is no evidence of the target."""
    return max(float(cells.left.mean()), float(cells.right.mean())) <= MAX_PAIR_SHARE


def cell_share(R: np.ndarray, t: np.ndarray, alpha: np.ndarray, inner_uv: np.ndarray, cells: StereoCells,
               rig: Rig) -> np.ndarray:
    """(P,): at poses (R (P, 3, 3) or (3, 3), t mm, alpha px/mm) the share of the inner points
    `inner_uv` (photo px) on the photo's colours, the worse camera's (a point outside an image is off)."""
    shares = []
    for uv, img in zip(project_uv(R, t, alpha, inner_uv, rig), (cells.left, cells.right)):
        r, c, inside = nearest_pixel(uv, img.shape)
        shares.append((img[r, c] & inside).mean(axis=-1))
    return np.minimum(shares[0], shares[1])
