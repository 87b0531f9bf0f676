"""vision/hue_layout.py: seeds from where the photo's hue layout agrees."""

from __future__ import annotations

import numpy as np

from photoservo.vision.hue_layout import BINS, agreement_peaks


def test_a_peak_grows_to_the_largest_box_that_agrees_as_well():
    """A single-hued target 140 x 120 px, 3 % of it reading another hue except in a clean corner:
    a small box in that corner agrees perfectly, a box of the target's size 0.97 as well. The best
    peak stays a small box inside it (the peaks as before), and its grown box is the large
    one at the target's middle (Middlebury's aloe pot: every island seeded on a small box inside
    it, every fit 3-8x too small)."""
    rng = np.random.default_rng(0)
    hue = np.full((300, 400), 90, np.uint8)
    hue[100:220, 140:280] = 15
    speck = rng.random((120, 140)) < 0.03
    speck[:24, :24] = False
    hue[100:220, 140:280][speck] = 90
    shares = np.zeros(BINS)
    shares[1] = 1.0  # hue 15: the middle of bin 1
    peaks, grown = agreement_peaks(hue, shares, np.geomspace(12, 150, 7))
    assert peaks[0][2] < 20 and 140 <= peaks[0][0] <= 280 and 100 <= peaks[0][1] <= 220
    u, v, d, a = grown[0]
    assert a > 0.95
    assert 90 < d < 120
    assert 175 <= u <= 245 and 130 <= v <= 190
