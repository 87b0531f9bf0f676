"""The tracker's re-acquisition (issue 10, vision/tracker.py), its pure parts: which candidate
of a whole-volume search continues a track, whether its final answer is the provisional one the
track started from, which target-hue blob pairs lie near a lost track, and the search window that
grows across the view while the depth stays held.
"""

from __future__ import annotations

from collections.abc import Generator
from dataclasses import dataclass, field

import numpy as np

from photoservo.geometry import heading_tilt_error
from photoservo.vision.detection import Detection
from photoservo.vision.estimator import Acquired, EstimatorParams
from photoservo.vision.fitness import StereoHue
from photoservo.vision.ga import Region
from photoservo.vision.photo_model import PhotoModel
from photoservo.vision.genes import GeneSpace
from photoservo.vision.pose_search import Candidate
from photoservo.vision.rig import Rig
from photoservo.vision.seeding import BlobPair, blob_pairs

DEPTH_GENE = 2  # the depth gene along the left camera's axis (inverse depth q, or z) in both codings


@dataclass
class Acquiring:
    """A whole-volume search in progress (`estimator.acquisition`) and the frame it runs on (left
    camera at T_base_left, base frame mm; capture time t, s). `provisional`: where the search puts
    its one island's (Detection, Candidate) before the refinements (`acquisition(provisional=)`);
    `taken`: that candidate once the tracker took it (the search then goes on behind the track
    until its final answer; as a whole-volume search again when the track is lost), with `before`,
    the track's alpha (px/mm) and predicted position at t (base frame mm, None: no track) from
    before it: the final answer is chosen as if the provisional one never was."""

    steps: Generator[int, None, Acquired]
    frame: StereoHue
    T_base_left: np.ndarray
    t: float
    provisional: list[tuple[Detection, Candidate]] = field(default_factory=list)
    tried: bool = False  # the provisional answer was tried (taken, or the search goes on as before)
    counted: bool = False  # counted in the tracker's acquisitions (its provisional answer was taken)
    taken: Candidate | None = None
    before: tuple[float | None, np.ndarray | None] | None = None


def same_answer(a: Candidate, b: Candidate, position_mm: float, heading_deg: float, size_tolerance: float) -> bool:
    """Two poses of one frame (left camera, mm) the same answer: positions within position_mm, the
    heading about the normal within heading_deg (a head-to-tail twin is not; the tilt is what the
    refinements correct: the stereo plane step turned sim first answers by 12-24 deg), alpha
    within size_tolerance."""
    return (float(np.linalg.norm(a.position_mm - b.position_mm)) <= position_mm
            and heading_tilt_error(a.R, b.R)[0] <= heading_deg and abs(b.alpha / a.alpha - 1.0) <= size_tolerance)


def choose(results: list[tuple[Detection, Candidate]], T_base_left: np.ndarray, alpha: float | None,
           p_pred: np.ndarray | None, size_tolerance: float) -> tuple[Detection, Candidate] | None:
    """The candidate of a whole-volume search (`estimator.acquisition`'s ranked results, poses in
    the left camera at T_base_left, base frame mm) that continues a track: with a track before
    (its alpha px/mm and predicted position p_pred, base frame mm), among the candidates that
    passed detection those of its size (alpha within size_tolerance), the nearest to p_pred;
    without one, `estimate`'s answer: the best-standing candidate if it passed. None when none
    qualifies."""
    if alpha is None or p_pred is None:
        return results[0] if results and results[0][0].passed else None
    passed = [(d, c) for d, c in results if d.passed]
    same = [(d, c) for d, c in passed if abs(c.alpha / alpha - 1.0) <= size_tolerance]

    def dist(dc: tuple[Detection, Candidate]) -> float:
        return float(np.linalg.norm(T_base_left[:3, :3] @ dc[1].position_mm + T_base_left[:3, 3] - p_pred))
    return min(same, key=dist) if same else None


def near_pairs(frame: StereoHue, model: PhotoModel, rig: Rig, p: EstimatorParams, p_pred: np.ndarray,
               reach_mm: float) -> tuple[list[BlobPair], bool]:
    """The frame's target-hue blob pairs (`seeding.blob_pairs`) whose triangulated position lies
    within reach_mm of the predicted position p_pred (left camera frame, mm), and whether any
    lie farther away."""
    pairs = blob_pairs(frame.left, frame.right, model, rig, p)
    near = [bp for bp in pairs if np.linalg.norm(bp.position_mm - p_pred) <= reach_mm]
    return near, len(pairs) > len(near)


def window_region(space: GeneSpace, R: np.ndarray, t: np.ndarray, alpha: float, across_mm: float, along_mm: float,
                  heading_deg: float, tilt_deg: float, alpha_frac: float) -> Region:
    """`GeneSpace.window` around a pose (left camera frame, mm) with the position +- across_mm
    across the line of sight and +- along_mm along it (depth): a floating creature drifts across
    the view, and a held depth with the scale's window holds alpha near the track's."""
    across = space.window(R, t, alpha, across_mm, heading_deg, tilt_deg, alpha_frac)
    along = space.window(R, t, alpha, along_mm, heading_deg, tilt_deg, alpha_frac)
    lo, hi = across.lo.copy(), across.hi.copy()
    lo[DEPTH_GENE], hi[DEPTH_GENE] = along.lo[DEPTH_GENE], along.hi[DEPTH_GENE]
    return Region.box(lo, hi, across.periodic)
