"""The photo's colours over hue and saturation (vision/colour_cells.py) and detection's cue on them
(`detection.photo_colours`): where the contour rule bounds the target, a candidate's inner points must
lie on the photo's colours at least as often as the model's placements elsewhere do at their upper
quantile. The motorcycle pair (the CI's real pair): every true pose stands above its placements; the
aloe pair's upright leaf at 0.6x: tests/test_aloe_pair.py."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from photoservo.config import load_config
from photoservo.vision.hs_cells import (
    CELL_HUES,
    CELL_MIN_SATURATION,
    CELL_SATURATIONS,
    cell_image,
    photo_cells,
)

CFG = load_config(None, ["estimator.z_min_mm=500", "estimator.z_max_mm=5000"])


def _hsv_bgr(h: int, s: int, v: int, shape=(20, 20)) -> np.ndarray:
    hsv = np.zeros(shape + (3,), np.uint8)
    hsv[...] = (h, s, v)
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)


def test_cells_keep_the_target_s_pale_and_saturated_colours_and_not_a_speck():
    """A pale green target (saturation 40, under the fitness' floor of 60) with a saturated half and one
    red pixel: both greens are cells, the speck (under 2 % of the target) is not; the backdrop, outside
    the mask, adds none. A pixel of the target's hue at another saturation level is off the cells, and
    so is a grey one (under CELL_MIN_SATURATION)."""
    photo = _hsv_bgr(60, 40, 200, (40, 40))
    photo[:, 20:] = _hsv_bgr(60, 200, 200, (40, 20))
    photo[5, 5] = _hsv_bgr(0, 220, 200, (1, 1))[0, 0]
    photo[:4] = _hsv_bgr(120, 200, 200, (4, 40))  # backdrop
    mask = np.zeros((40, 40), np.uint8)
    mask[4:] = 255
    cells = photo_cells(photo, mask, CFG.fitness.min_value)
    hsv = cv2.cvtColor(photo, cv2.COLOR_BGR2HSV)
    kept = {(int(h), int(s)) for h, s in zip(*np.nonzero(cells))}
    green_pale = (int(hsv[10, 10, 0]) // CELL_HUES, int(hsv[10, 10, 1]) // CELL_SATURATIONS)
    green_full = (int(hsv[10, 30, 0]) // CELL_HUES, int(hsv[10, 30, 1]) // CELL_SATURATIONS)
    assert kept == {green_pale, green_full}
    frame = np.concatenate([photo, _hsv_bgr(60, 110, 200, (40, 40)), _hsv_bgr(60, CELL_MIN_SATURATION - 2, 200, (40, 40))],
                           axis=1)
    on = cell_image(frame, cells, CFG.fitness.min_value)
    assert on[10, 10] and on[10, 30] and not on[5, 5] and not on[1, 1]
    assert not on[:, 40:80].any() and not on[:, 80:].any()


def test_a_photo_without_pixels_over_the_floor_has_no_cells():
    photo = _hsv_bgr(60, 5, 200)
    assert not photo_cells(photo, np.full((20, 20), 255, np.uint8), CFG.fitness.min_value).any()


def test_every_true_pose_of_the_motorcycle_lies_on_the_photo_s_colours():
    """The motorcycle pair at full size, every target and photo (the contour rule's regime: the
    garage's wood within the red's hues): at the true pose the inner points lie on the photo's colours
    far more often than the model's placements elsewhere at their 0.9 quantile, and the true pose
    passes `detect` with the cue on."""
    pytest.importorskip("skimage")
    from photoservo.sim.middlebury import real_cases
    from photoservo.vision.colour_cells import stereo_cells
    from photoservo.vision.detection import detect, photo_colours
    from photoservo.vision.estimator import search_frame
    from photoservo.vision.fitness import stereo_hue
    from photoservo.vision.pose_search import Candidate

    for c in real_cases(CFG.photo_model):
        frame = search_frame(stereo_hue(c.left, c.right, CFG.fitness), c.model, c.left, c.right, CFG.estimator)
        assert frame.chroma is not None
        cells = stereo_cells(c.left, c.right, c.model.colour_cells, CFG.fitness.min_value)
        tr = c.truth
        truth = Candidate(np.eye(3), np.array(tr["position_mm"]), tr["alpha_px_per_mm"], 0.0, 0, "truth")
        own, null = photo_colours(truth, c.model, cells, c.rig)
        assert own > 0.7 and own > null + 0.1, (c.target, c.variant, own, null)
        d = detect(truth, c.model, frame, c.rig, CFG.fitness, CFG.estimator, cells=cells)
        assert d.passed and d.photo_colours == own, (c.target, c.variant, d)


def test_the_cells_judge_only_where_the_photo_s_colours_are_a_minority_of_the_pair():
    """The harbour generator's many-hued fish whose colours are the water's (1700, 1702, 1703): the
    photo's colours cover 0.65-0.97 of the pair, and the rendered fish lies on them less often than the
    water does, so the cue is off there (`distinctive`; with it on, the three were not found). Fish 1704
    (its colours 2 % of the pair) and every motorcycle photo (0.19-0.47) are judged."""
    import sys
    from pathlib import Path

    from photoservo.vision.colour_cells import MAX_PAIR_SHARE, distinctive, stereo_cells

    sys.path.insert(0, str(Path(__file__).parent))
    from _bench_scenes import harbour_scene

    for seed, judged in ((1700, False), (1702, False), (1703, False), (1704, True)):
        sc, model = harbour_scene(seed, kind="fish", many_hued=True)
        cells = stereo_cells(sc.left, sc.right, model.colour_cells, CFG.fitness.min_value)
        assert distinctive(cells) == judged, (seed, cells.left.mean(), cells.right.mean())
    pytest.importorskip("skimage")
    from photoservo.sim.middlebury import real_cases

    for c in real_cases(CFG.photo_model):
        cells = stereo_cells(c.left, c.right, c.model.colour_cells, CFG.fitness.min_value)
        assert distinctive(cells) and cells.left.mean() < MAX_PAIR_SHARE, (c.target, c.variant)
