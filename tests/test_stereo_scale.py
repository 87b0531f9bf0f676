"""The stereo plane under a rig whose focal lengths are off (vision/stereo_plane.py, `fit_target_plane(scale=True)`,
`_scale_shift`): the right image scaled by 1 % against the left tips the plane fitted with the written rig by 6
degrees at 1.2 m; measured from the rows' vertical offsets and taken out, the plane lies within a degree and a half
of the creature's (the answer is turned onto it: `candidates.scaled_plane`)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from photoservo.config import load_config
from photoservo.sim.scenes import random_scene
from photoservo.vision.fitness import stereo_hue
from photoservo.vision.photo_model import build_photo_model
from photoservo.vision.sampling import grey
from photoservo.vision.stereo_plane import fit_target_plane, on_target_hue

CFG = load_config()
# focal lengths 0.5 % off, no extra stereo rotation: seeds 2 and 16 have the right camera's 1 % short of the
# left's, 14 1 % long, 3 both alike
SYN = dataclasses.replace(CFG.synthetic, calib_rotation_deg=0.0, calib_focal_pct=0.5)


def _plane_off_deg(seed: int, scale: bool) -> tuple[float, float]:
    """(the plane's angle to the creature's normal at the truth pose (deg), the right camera's focal error
    relative to the left's)."""
    sc = random_scene(seed, SYN, CFG.photo_model, kind="fish", effects=("waves", "noise"), distance_mm=1200.0,
                      tilt_deg=20.0)
    model = build_photo_model(sc.photo, CFG.photo_model)
    R, t, alpha = np.array(sc.truth["rotation"]), np.array(sc.truth["position_mm"]), sc.truth["alpha_px_per_mm"]
    on = on_target_hue(model, stereo_hue(sc.left, sc.right, CFG.fitness).left)
    plane = fit_target_plane(R, t, alpha, model, grey(sc.left), grey(sc.right), sc.rig, on_target=on, scale=scale)
    assert plane is not None
    rel = (sc.rig_true.right.K[0, 0] / sc.rig.right.K[0, 0]) / (sc.rig_true.left.K[0, 0] / sc.rig.left.K[0, 0]) - 1
    return math.degrees(math.acos(min(1.0, abs(float(plane.normal @ R[:, 2]))))), rel


@pytest.mark.parametrize("seed", [2, 14, 16])
def test_the_right_images_scale_is_taken_out_of_the_plane(seed):
    off, rel = _plane_off_deg(seed, True)
    assert abs(rel) == pytest.approx(0.01, abs=1e-4)
    assert off < 1.5
    off_rig, _ = _plane_off_deg(seed, False)  # the written rig alone: the plane tipped
    assert off_rig > 4.0


def test_a_rig_without_scale_error_keeps_its_plane():
    off, rel = _plane_off_deg(3, True)
    assert rel == pytest.approx(0.0, abs=1e-9) and off < 1.5
