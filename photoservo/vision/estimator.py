"""Pose and size estimation from one stereo frame (method steps 3-5): GA islands
(`vision/pose_search.py`) seeded from the images (`vision/seeding.py`) search the photo-model's
pose and scale alpha against the stereo fitness of `vision/fitness.py`; `vision/detection.py`
decides whether the best is the creature.

Acquisition (`estimate`): the target's hues (the model's `target_hues`) are segmented in both
images; blobs are paired along the epipolar lines and triangulated, which gives (u, v, q), the
apparent scale s from the blob area and two heading hypotheses from the blob's principal axis.
Groups of pieces seed too: pairs near each other (`group_pairs`), one image's pieces matched with
the other's whole blob (`split_pairs`), and a foam band's pieces taken together where some paired
on their own and some did not (`bridged_pairs`: the gap between them is foam, `parts.foam_marked`).
Each pair seeds one GA island searching a window around it; an optional unseeded island
searches the whole volume. Every island stops when converged (`Convergence`); each island's best
is a candidate, tested by `detect` (`Detection`: the fitness with the cameras combined by their
minimum — both must see it — against the pair's own null, the outline check: few outer points
on target hue, and the parts check). An island whose fit has parts absent and lies near the best
island's tries its head-to-tail twin (`candidates.turned_islands`); where hue bounds the target, the
other islands near the best with their parts in place are turned onto the plane both images see
(`candidates.stereo_islands`); the island leading by fitness
is refined (its look-alike twins: planar-ambiguity mirror, heading + 180 deg; the stereo plane's
tilt; the per-axis size). The candidate that stands out most from what a search of this pair
finds elsewhere at its scale (`Detection.standing`) is the estimate, the others the candidate
list, and `found` is whether it passed (a fit on a small spot of the target's colour may pass
while the creature itself stands out more: then the creature is the estimate, or nothing is) —
unless it fails and one that passes stands nearly as high as the best failing for another reason than
parts on bare water (`candidates.ranked`). When the first
still fails after its head-to-tail twin was tried, each candidate that fails its outline test
alone is tried grown (`candidates.grown_outlines`: a fit shrunk inside the creature spills onto
the creature itself), then each that fails its parts alone is re-fitted at quarter turns
(`candidates.parted_turns`: a fit at the creature's place with its heading off has the model's
legs beside the creature's; where hue bounds the target and no turn passes, it is turned onto the plane
both images see under it, a fit tilted off the creature having them beside it too), then each whose
outline spills, whatever its parts say, is re-fitted at quarter turns grown (`candidates.grown_turns`: a
fit shrunk inside the creature and turned on it), then, where hue bounds the target and `foam_turns` is on
(off in configs/default.toml: it found renderer look-alike null 1853), each that fails its parts alone is
re-fitted at quarter turns counting its inner points on foam as matches (`candidates.foam_turns`: a fit
beside a foam band across the creature outscores the whole creature, whose points under the band score
0). Where hue bounds the target, a first candidate that passes is searched
again on the plane both images see under it where its tilt contradicts that plane
(`candidates.stereo_tilt`), and at the depth both images see under it (`candidates.stereo_depth`).

When the target's hues cover most of the pair (a many-hued creature in water of one of its hues;
a real scene whose background lies within the hue tolerance of the target), seeds come from the
hue layout (`vision/hue_layout.py`) and from the photo's silhouette on the hues the creature
holds more of than the frame does (`vision/silhouette.py`), alternately.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Generator
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from photoservo.errors import InputError
from photoservo.vision.appearance import stereo_grey, stereo_saturation, stereo_value
from photoservo.vision.bare_parts import stereo_water
from photoservo.vision.candidates import (appearance_twin, foam_turns, grown_outlines, grown_turns, parted_turns,
                                          ranked, refined, same_surface_first, scaled_plane, stereo_depth,
                                          stereo_islands, stereo_tilt, turned_islands)
from photoservo.vision.contour import stereo_chroma
from photoservo.vision.colour_cells import distinctive, stereo_cells
from photoservo.vision.detection import Detection, detect
from photoservo.vision.fitness import FitnessParams, StereoHue, stereo_hue
from photoservo.vision.ga import GAParams
from photoservo.vision.hue_layout import layout_pairs
from photoservo.vision.parts import foam_marked, model_parts
from photoservo.vision.photo_model import HUE_BINS, PhotoModel
from photoservo.vision.pose_search import Candidate, PoseSearch, drive
from photoservo.vision.rig import Rig
from photoservo.vision.seeding import (
    BlobPair,
    ModelShape,
    group_pairs,
    match_blobs,
    seed_genes,
    bridged_pairs,
    split_pairs,
    stereo_blobs,
    target_mask,
)
from photoservo.vision.silhouette import distinctive_weight, silhouette_pairs


# the spawn key of the bridged islands' random streams (`acquisition`): a child of the seed that the
# acquisition's own spawns (a few dozen) never reach, so that the other islands draw as without them
BRIDGED_STREAMS = 1 << 20
# the hue layout's grown islands' (`_islands`): the same child, as the two never seed one acquisition
# (bridged islands where hue bounds the target, grown ones where it does not)
GROWN_STREAMS = BRIDGED_STREAMS
GROWN = "grown"  # the grown islands' names' start


@dataclass(frozen=True)
class EstimatorParams:
    """[estimator] config: search volume, seeding, convergence and detection."""

    genes: Literal["image", "cartesian"]  # gene coding (module docstring)
    z_min_mm: float  # nearest depth searched (mm)
    z_max_mm: float  # farthest depth searched (mm)
    tilt_max_deg: float  # largest tilt of the model normal from the optical axis (deg)
    alpha_min: float  # smallest photo ratio alpha (px/mm)
    alpha_max: float  # largest photo ratio alpha (px/mm)
    min_apparent_px: float  # smallest target size in the image searched (px, longest side)
    seeding: bool  # seed islands from target-hue blobs matched along epipolar lines
    global_island: bool  # also run one unseeded island over the whole volume
    max_candidates: int  # at most this many blob pairs seed islands
    min_blob_px: int  # smallest target-hue blob (px) used as a seed
    epipolar_tol_px: float  # blob centroids this far from the epipolar line still pair (px)
    window_depth: float  # seeded window: inverse depth +- this fraction
    window_scale: float  # seeded window: ln s +- this
    window_grow: float  # seeded window: ln s reaches this far above the blob's (the blob may be a piece)
    layout_share: float  # seed from the hue layout when seeding.target_mask holds more than this share of hued px
    contour_rule: bool  # where the target's hues are everywhere, the fitness judges outer points by colour edges
    contour_grow: float  # ...and the leading island's fit is refined, then tried grown by sqrt(this) and this (1 = off)
    group_reach: float  # blob pairs group when their gap is <= this x the sum of their half-lengths
    plane_refine: bool  # correct the tilt by a stereo plane fit over the inner points (vision/stereo_plane.py)
    plane_fitness_tol: float  # ...accepted when the re-fitted pose's fitness is at most this below the GA's
    aspect_max: float  # per-axis size: photo columns vs rows scaled apart by at most this factor (1 = off)
    aspect_min_gain: float  # ...taken when the fitness rises by at least this
    min_generations: int  # never stop before this many generations
    max_generations: int  # always stop after this many generations
    patience: int  # converged: no improvement beyond the tolerances for this many generations
    fitness_tol: float  # ... best fitness rose by less than this
    position_tol_mm: float  # ... best position moved less than this (mm)
    rotation_tol_deg: float  # ... best rotation turned less than this (deg)
    alpha_tol: float  # ... best alpha changed by less than this fraction
    min_contrast: float  # detection: found = contrast over the pair's own null >= this (vision/detection.py)
    max_outer_on_target: float  # detection also needs at most this share of outer points on target hue
    max_outer_if_appearance: float  # ...or at most this share when both appearance cues reach min_appearance
    min_appearance: float  # appearance cues (vision/appearance.py) that excuse an outline spill
    max_absent_parts: float  # detection also needs at most this share of the model's parts absent (vision/parts.py)
    bare_water_z: float  # ...and of two or more absent parts none on bare water within this many standard
    # errors of the water's colour around the candidate (vision/bare_parts.py; 0 = off)
    foam_part_share: float  # ...both judging no part with this share of its points on foam where this share of the
    # model's lies on foam in both cameras (vision/parts.py: a part straddling a foam band's edge; 1 = off)
    outline_distinctive: bool  # an outer point on a target hue spills by how much more the creature holds of that
    # hue than the pair does (silhouette.distinctive_weight), not wholly (vision/detection.py)
    outline_grow: float  # when the first candidate fails, one failing its outline alone is tried grown by sqrt(this)
    # and this (`grown_outlines`; 1 = off)
    parted_turns: bool  # ...and one failing its parts alone re-fitted at quarter turns (`candidates.parted_turns`)
    grown_turns: bool  # ...and one whose outline spills re-fitted at quarter turns, grown (`candidates.grown_turns`)
    foam_turns: bool  # ...and one failing its parts alone re-fitted at quarter turns counting foam (`foam_turns`)
    foam_bridge: bool  # seed islands also from pieces joined across foam, some paired alone (`seeding.bridged_pairs`)
    passed_standing_ratio: float  # a candidate that passes ranks first when it stands >= this x the top, which fails
    twin_appearance: bool  # let the appearance cue choose between the first candidate and its head-to-tail twin
    twin_min_appearance: float  # ...the twin is taken when its appearance score is at least this,
    twin_appearance_margin: float  # ...at least this above the candidate's,
    twin_fitness_tol: float  # ...and its fitness at most this below the candidate's
    island_turn_gain: float  # each island's head-to-tail twin is kept when it fits at least this much better
    island_turn_within: float  # ...tried for the islands whose fit is within this of the best island's fitness
    confidence_scale: float  # width of the logistic confidence around min_contrast

    def validate(self, where: str) -> None:
        w = f"{where}." if where else ""
        checks = [
            ("z_min_mm", 0 < self.z_min_mm < self.z_max_mm, "need 0 < z_min_mm < z_max_mm"),
            ("tilt_max_deg", 0 <= self.tilt_max_deg < 90, "must be in [0, 90)"),
            ("alpha_min", 0 < self.alpha_min < self.alpha_max, "need 0 < alpha_min < alpha_max"),
            ("min_apparent_px", self.min_apparent_px > 0, "must be > 0"),
            ("max_candidates", self.max_candidates >= 0, "must be >= 0"),
            ("min_blob_px", self.min_blob_px >= 1, "must be >= 1"),
            ("epipolar_tol_px", self.epipolar_tol_px > 0, "must be > 0"),
            ("window_depth", 0 < self.window_depth < 1, "must be in (0, 1)"),
            ("window_scale", self.window_scale > 0, "must be > 0"),
            ("window_grow", self.window_grow >= 0, "must be >= 0"),
            ("aspect_max", self.aspect_max >= 1.0, "must be >= 1"),
            ("layout_share", 0.0 <= self.layout_share <= 1.0, "must be in [0, 1]"),
            ("contour_grow", self.contour_grow >= 1.0, "must be >= 1"),
            ("outline_grow", self.outline_grow >= 1.0, "must be >= 1"),
            ("group_reach", self.group_reach >= 0, "must be >= 0"),
            ("passed_standing_ratio", 0.0 <= self.passed_standing_ratio <= 1.0, "must be in [0, 1]"),
            ("twin_min_appearance", -1.0 <= self.twin_min_appearance <= 1.0, "must be in [-1, 1]"),
            ("twin_appearance_margin", self.twin_appearance_margin >= 0, "must be >= 0"),
            ("twin_fitness_tol", self.twin_fitness_tol >= 0, "must be >= 0"),
            ("island_turn_gain", self.island_turn_gain >= 0, "must be >= 0"),
            ("island_turn_within", self.island_turn_within >= 0, "must be >= 0"),
            ("max_outer_if_appearance", 0.0 <= self.max_outer_if_appearance <= 1.0, "must be in [0, 1]"),
            ("max_absent_parts", 0.0 <= self.max_absent_parts <= 1.0, "must be in [0, 1]"),
            ("bare_water_z", self.bare_water_z >= 0, "must be >= 0"),
            ("foam_part_share", 0.0 < self.foam_part_share <= 1.0, "must be in (0, 1]"),
            ("min_generations", 0 <= self.min_generations <= self.max_generations,
             "need 0 <= min_generations <= max_generations"),
            ("patience", self.patience >= 1, "must be >= 1"),
            ("confidence_scale", self.confidence_scale > 0, "must be > 0"),
        ]
        for key, ok, msg in checks:
            if not ok:
                raise InputError(f"config key '{w}{key}': {msg}, got {getattr(self, key)}")
        if not self.seeding and not self.global_island:
            raise InputError(f"config key '{w}seeding': with global_island = false, seeding must be true")


@dataclass(frozen=True)
class Estimate:
    """The estimator's answer (DESIGN.md "Estimate (JSON)"). Pose fields are None when not found."""

    found: bool
    position_mm: np.ndarray | None
    rotation: np.ndarray | None
    alpha_px_per_mm: float | None
    size_mm: tuple[float, float] | None
    fitness: float | None
    generations: int
    seconds: float
    confidence: float
    evaluations: int = 0
    candidates: tuple[dict, ...] = field(default_factory=tuple)
    detection_score: float | None = None
    contrast: float | None = None  # the best candidate's contrast over the pair's null (vision/detection.py)
    alpha_xy_px_per_mm: tuple[float, float] | None = None  # per photo axis (Candidate.alpha_xy)

    def to_json(self, with_candidates: bool = False) -> dict:
        """Exactly the DESIGN.md estimate object (plus `confidence`, `evaluations` and, when asked,
        `candidates`)."""
        def lst(a):
            return None if a is None else [float(x) for x in np.ravel(a)]
        out = {
            "found": bool(self.found),
            "position_mm": lst(self.position_mm),
            "rotation": None if self.rotation is None else [lst(r) for r in np.asarray(self.rotation)],
            "alpha_px_per_mm": None if self.alpha_px_per_mm is None else float(self.alpha_px_per_mm),
            "alpha_xy_px_per_mm": lst(self.alpha_xy_px_per_mm),
            "size_mm": lst(self.size_mm),
            "fitness": None if self.fitness is None else round(float(self.fitness), 6),
            "generations": int(self.generations),
            "seconds": round(float(self.seconds), 4),
            "confidence": round(float(self.confidence), 4),
            "detection_score": None if self.detection_score is None else round(float(self.detection_score), 6),
            "contrast": None if self.contrast is None else round(float(self.contrast), 6),
            "evaluations": int(self.evaluations),
        }
        if with_candidates:
            out["candidates"] = list(self.candidates)
        return out


def _islands(model: PhotoModel, rig: Rig, frame: StereoHue, ga_params: GAParams, p: EstimatorParams,
             fit_params: FitnessParams, ss: np.random.SeedSequence,
             seeded_only: bool = False, foam: StereoHue | None = None,
             bridge_ss: np.random.SeedSequence | None = None) -> list[tuple[str, PoseSearch]]:
    """The acquisition's GA islands (module docstring): one per seed pair, at most
    max_candidates, largest first; an unseeded one over the whole volume when asked or when
    nothing seeds (never with `seeded_only`); then, with `foam` (the frame with its foam marked,
    `parts.foam_marked`), one per pair of pieces joined across foam (`seeding.bridged_pairs`, at
    most max_candidates, named "bridged k"), on streams of `bridge_ss`: the other islands are
    those of a pair without such pieces. Where the hue layout seeds (never with bridged islands),
    also one per grown box (`hue_layout.layout_pairs`, at most `GROWN_ISLANDS`, named "grown k"),
    last, on streams of their own."""
    islands: list[tuple[str, PoseSearch]] = []
    bridged: list[BlobPair] = []
    grown: list[BlobPair] = []
    shape = ModelShape.of(model)
    if p.seeding and p.genes == "image":
        if hues_everywhere(frame, model, p):
            # the creature's hues are everywhere (a many-hued creature, the water's hue among its
            # own; not target hues scattered by noise over water at the edge of the tolerance,
            # which target_mask leaves out): seed from where the photo's hue layout agrees (vision/hue_layout.py)
            # and from where the photo's silhouette fits the hues the creature holds more of
            # than the frame does (vision/silhouette.py), alternately
            layout, grown = layout_pairs(frame.left, frame.right, model, shape.area, rig, p)
            both = (silhouette_pairs(frame.left, frame.right, model, rig, p), layout)
            pairs = [bp for k in range(max(map(len, both))) for src in both for bp in src[k:k + 1]]
        else:
            left, right = stereo_blobs(frame.left, frame.right, model, p)
            pairs = match_blobs(left, right, rig, p)
            if foam is not None:  # a foam band's pieces paired unevenly, taken together
                bridged = bridged_pairs(left, right, pairs, foam, model.target_hues, rig, p)[: p.max_candidates]
            # groups of pieces (a creature split by foam: in both images, or in one only) beside
            # the single blobs, largest first
            pairs = sorted(group_pairs(pairs, p) + split_pairs(left, right, pairs, rig, p) + pairs,
                           key=lambda bp: -bp.left.area)
        pairs = pairs[: p.max_candidates]
        for i, (pair, s) in enumerate(zip(pairs, ss.spawn(len(pairs)))):
            islands.append((f"blob {i}", _seeded(pair, shape, s, model, rig, frame, ga_params, p, fit_params)))
    if (p.global_island or not islands) and not seeded_only:
        rng = np.random.default_rng(ss.spawn(1)[0])
        islands.append(("global", PoseSearch(model, rig, frame, ga_params, p, fit_params, rng)))
    if bridged and bridge_ss is not None:
        for i, (pair, s) in enumerate(zip(bridged, bridge_ss.spawn(len(bridged)))):
            islands.append((f"bridged {i}", _seeded(pair, shape, s, model, rig, frame, ga_params, p, fit_params)))
    # the hue layout's grown boxes (a single-hued target agrees best on a small box inside it:
    # hue_layout.agreement_peaks), islands of their own after the others, on streams of their own
    # (the other islands' and everything ss spawns later as without them)
    extra = np.random.SeedSequence(ss.entropy, spawn_key=(*ss.spawn_key, GROWN_STREAMS))
    for i, (pair, s) in enumerate(zip(grown, extra.spawn(len(grown)))):
        islands.append((f"{GROWN} {i}", _seeded(pair, shape, s, model, rig, frame, ga_params, p, fit_params)))
    return islands


def _seeded(pair: BlobPair, shape: ModelShape, s: np.random.SeedSequence, model: PhotoModel, rig: Rig,
            frame: StereoHue, ga_params: GAParams, p: EstimatorParams, fit_params: FitnessParams) -> PoseSearch:
    """One island seeded from a blob pair (`seed_genes`) on the random stream `s`."""
    rng = np.random.default_rng(s)
    search = PoseSearch(model, rig, frame, ga_params, p, fit_params, rng)
    seeds, region = seed_genes(pair, shape, search.space, rng, ga_params.population)
    search.ga.set_region(region)
    search.ga.genes[:] = seeds
    return search


def apparent_size(c: Candidate) -> float:
    """A fit's size in the images, up to the cameras' focal length: the photo's pixels over alpha (px/mm)
    at depth z (mm), 1 / (alpha z)."""
    return 1.0 / (c.alpha * c.position_mm[2])


def hues_everywhere(frame: StereoHue, model: PhotoModel, p: EstimatorParams) -> bool:
    """More than `layout_share` of the left image's hued pixels lie in the model's target hues
    (`seeding.target_mask`: not hues scattered by noise at the edge of the tolerance): hue cannot
    bound the target in this pair (a many-hued creature in water of one of its hues; a real
    background within the target's hue tolerance)."""
    hued = int(np.count_nonzero(frame.left < HUE_BINS))
    return bool(hued) and np.count_nonzero(target_mask(frame.left, model.target_hues)) > p.layout_share * hued


def search_frame(frame: StereoHue, model: PhotoModel, left_bgr: np.ndarray, right_bgr: np.ndarray,
                 p: EstimatorParams) -> StereoHue:
    """The frame the acquisition scores poses on: with the pair's chroma (the contour rule,
    vision/contour.py) where `contour_rule` is on and hue cannot bound the target
    (`hues_everywhere`), else `frame` as it is."""
    if p.contour_rule and frame.chroma is None and hues_everywhere(frame, model, p):
        return dataclasses.replace(frame, chroma=stereo_chroma(left_bgr, right_bgr))
    return frame


@dataclass(frozen=True)
class Acquired:
    """What an acquisition ends with: every island's best with its detection test, ranked by
    standing (vision/detection.py), then fitness; the islands (their generations, evaluations)."""

    results: list[tuple[Detection, Candidate]]
    islands: list[tuple[str, PoseSearch]]


def acquisition(model: PhotoModel, left_bgr: np.ndarray, right_bgr: np.ndarray, rig: Rig, ga_params: GAParams,
                p: EstimatorParams, fit_params: FitnessParams, frame: StereoHue, seed: int = 0,
                seeded_only: bool = False, provisional: list[tuple[Detection, Candidate]] | None = None
                ) -> Generator[int, None, Acquired]:
    """The acquisition from the whole volume (module docstring) in steps: yields the GA
    generations each step ran (one island generation, or one of the leading island's
    refinements: its twins, the stereo plane fit, the per-axis size) and returns the ranked
    candidates. `estimate` runs it to its end on one frame; the tracker runs a share of it per
    camera frame (vision/tracker.py). `seeded_only`: no unseeded island over the whole volume
    (no candidate at all when nothing seeds). `provisional` (the tracker's): when there is one
    island, its fit (after its turned twin) and that fit's detection are appended there as
    (Detection, Candidate) once it converged, before the refinements and the final detection
    (the ranking has nothing to choose; the answer is the same island's, refined); the rest of
    the acquisition and its answer are unchanged."""
    ss = np.random.SeedSequence(seed)
    bridge_ss = np.random.SeedSequence(seed, spawn_key=(BRIDGED_STREAMS,))  # the bridged islands' own streams
    frame = search_frame(frame, model, left_bgr, right_bgr, p)
    # the pair's brightness and its foam (`parts.foam_marked`), read by the seeding and by every detection
    value = stereo_value(left_bgr, right_bgr)
    foam = foam_marked(frame, value.left, value.right) if p.foam_part_share < 1.0 or p.foam_bridge else None
    islands = _islands(model, rig, frame, ga_params, p, fit_params, ss, seeded_only,
                       foam=foam if p.foam_bridge else None, bridge_ss=bridge_ss)
    if not islands:
        return Acquired([], [])
    n_bridged = sum(name.startswith("bridged") for name, _ in islands)

    def spawn() -> list[np.random.SeedSequence]:  # one stream per island; a bridged island's from its own sequence
        return ss.spawn(len(islands) - n_bridged) + bridge_ss.spawn(n_bridged)

    # the hue layout's grown islands (`_islands`, last; never with bridged ones) take no part in what
    # the others do as without them: their turned twins apart, and refined apart (below)
    n = sum(not name.startswith(GROWN) for name, _ in islands)
    streams = spawn()  # the islands' turned twins' own random streams
    firsts = []
    for _, search in islands:
        firsts.append((yield from search.steps()))
    parts = model_parts(model.inner_uv)
    for lo, hi in ((0, n), (n, len(islands))):
        some = firsts[lo:hi]
        yield from turned_islands(some, islands[lo:hi], streams[lo:hi], parts, p)
        firsts[lo:hi] = some
    if frame.chroma is None:  # where hue bounds the target: the islands near the lead on their stereo planes
        yield from stereo_islands(firsts, islands, spawn(), left_bgr, right_bgr, parts, p)
    # what every candidate's detection reads of the pair, computed once per acquisition
    looks = dict(grey_frame=stereo_grey(left_bgr, right_bgr), value_frame=value,
                 parts=parts, chroma=frame.chroma or stereo_chroma(left_bgr, right_bgr),
                 weight=(distinctive_weight(frame.left, frame.right, model)
                         if p.outline_distinctive and frame.chroma is None else None),
                 foam=foam if p.foam_part_share < 1.0 else None)
    # the water's colour in each image, for detection's outline on another object (where hue bounds the target)
    looks["water"] = stereo_water(model, frame, looks["chroma"]) if frame.chroma is None else None
    # ...and its saturation, for the body's colour against the photo's (where hue bounds the target)
    looks["saturation_frame"] = (stereo_saturation(left_bgr, right_bgr, frame.saturation) if frame.chroma is None
                                 else None)
    # ...and the pair's pixels on the photo's colours, for its inner points where the contour rule bounds the
    # target and those colours are a minority of the pair (vision/colour_cells.py)
    cells = (stereo_cells(left_bgr, right_bgr, model.colour_cells, fit_params.min_value)
             if frame.chroma is not None and model.colour_cells.any() else None)
    looks["cells"] = cells if cells is not None and distinctive(cells) else None
    if provisional is not None and len(islands) == 1 and np.isfinite(firsts[0].fitness):
        provisional.append((detect(firsts[0], model, frame, rig, fit_params, p, seed=seed, **looks),
                            dataclasses.replace(firsts[0], source=islands[0][0])))
    # the leading island's fit is refined (`refined`), before detection
    lead = int(np.argmax([c.fitness for c in firsts[:n]])) if n else None
    if n < len(islands):  # the best grown island fitting better than the others' lead: refined too
        best = n + int(np.argmax([c.fitness for c in firsts[n:]]))
        grown_lead = best if lead is None or firsts[best].fitness > firsts[lead].fitness else None
    else:
        grown_lead = None
    # ...and every other grown island whose fit is larger in the images than the lead's by more than the lead's
    # own grown fits reach (`refined`: contour_grow): a grown box seeds near a single-hued target's size, where
    # the island's GA ends on the flank of its peak, below the small fits inside the target until refined (the
    # aloe pot from the left image seeds 3-5: 0.68-0.74 against the lead's 0.73-0.74 at 72-79 % small; refined
    # 0.83-0.86, 1.5-4.7 % in size). Within that reach the lead's refinement covers it (the motorcycle crate at
    # 0.6x seed 5: a grown fit 1.3x the lead's, refined, replaced the lead's fit at the same place and size)
    beyond = [k for k in range(n, len(islands)) if lead is not None and k != grown_lead
              and apparent_size(firsts[k]) > p.contour_grow * apparent_size(firsts[lead])]
    # (the ladder run again after a slide from two surfaces, `refined`'s settle, for the others' lead only: on
    # grown islands it reached fits past the crate higher by less than a point, the motorcycle's crate from the
    # left image seed 12, 0.865 -> 0.870 at 7.7 -> 47.1 % in size, at 0.6x seed 33 0.947 at 31.2 % against the
    # lead's 0.943 at 1.7 %)
    for k in (lead, grown_lead, *beyond):
        if k is not None:
            firsts[k] = yield from refined(islands[k][1], firsts[k], frame, left_bgr, right_bgr, p, settle=k == lead)
    # a grown island's fit is a candidate only where, refined, it fits better than every other island's:
    # else the others' candidates as without it (the motorcycle's crate at 0.6x seed 31: a grown fit 26 %
    # too large, 0.925 against the others' 0.934, stood higher and became the answer)
    bar = max((c.fitness for c in firsts[:n]), default=-np.inf)
    results = []
    for k, ((name, search), c) in enumerate(zip(islands, firsts)):
        if np.isfinite(c.fitness) and (k < n or c.fitness > bar):
            results.append((detect(c, model, frame, rig, fit_params, p, seed=seed, **looks),
                            dataclasses.replace(c, source=name)))
    results = ranked(results, p.passed_standing_ratio)
    if frame.chroma is not None:  # hues everywhere: a pose's two images may lie on two parts of the target's hues
        results = same_surface_first(results, model, frame, rig, looks["grey_frame"], p.passed_standing_ratio)
    if p.twin_appearance and results:
        search = dict(islands)[results[0][1].source]
        results[0] = yield from appearance_twin(results[0], search, looks["grey_frame"], p, seed, looks["value_frame"],
                                                looks["parts"], looks["chroma"], looks["weight"], looks["foam"],
                                                looks["cells"], looks["saturation_frame"])
    if p.outline_grow > 1.0 and results and not results[0][0].passed:  # after the twin: it draws from the islands' rng
        results = yield from grown_outlines(results, dict(islands), looks, p, seed)
    if p.parted_turns and results and not results[0][0].passed:  # after the grown outlines (own streams)
        results = yield from parted_turns(results, dict(islands), looks, p, seed, left_bgr, right_bgr)
    if p.grown_turns and results and not results[0][0].passed:  # after the parted turns (own streams)
        results = yield from grown_turns(results, dict(islands), looks, p, seed)
    if p.foam_turns and results and not results[0][0].passed:  # after the grown turns (own streams)
        results = yield from foam_turns(results, dict(islands), looks, p, seed)
    if frame.chroma is None and results:  # where hue bounds the target: the answer on the plane and at the depth
        search = dict(islands)[results[0][1].source]  # both images see
        results[0] = yield from stereo_tilt(results[0], search, left_bgr, right_bgr, looks, p, seed)
        results[0] = yield from stereo_depth(results[0], search, left_bgr, right_bgr, ss.spawn(1)[0], looks, p, seed)
        if p.plane_refine:
            results[0] = scaled_plane(results[0], search, left_bgr, right_bgr, p)
    return Acquired(results, islands)


def estimate(model: PhotoModel, left_bgr: np.ndarray, right_bgr: np.ndarray, rig: Rig,
             ga_params: GAParams, est_params: EstimatorParams, fit_params: FitnessParams,
             seed: int = 0, frame: StereoHue | None = None) -> Estimate:
    """Acquire the target in one stereo frame from the default search volume (module docstring).
    Same inputs and seed, same result."""
    t0 = time.perf_counter()
    for name, img, cam in (("left", left_bgr, rig.left), ("right", right_bgr, rig.right)):
        if img.shape[1] != cam.width or img.shape[0] != cam.height:
            raise InputError(f"{name} image is {img.shape[1]}x{img.shape[0]} px but the rig's "
                             f"[{name}] size is {cam.width}x{cam.height}")
    frame = frame or stereo_hue(left_bgr, right_bgr, fit_params, saturation=True)  # the pair's HSV once
    done = drive(acquisition(model, left_bgr, right_bgr, rig, ga_params, est_params, fit_params, frame, seed))
    results, islands = done.results, done.islands
    evaluations = sum(search.ga.evaluations for _, search in islands)
    cands = tuple(_candidate_json(c, d, model) for d, c in results)
    seconds = time.perf_counter() - t0
    if not results or not results[0][0].passed:
        d, best = results[0] if results else (None, None)
        return Estimate(found=False, position_mm=None, rotation=None, alpha_px_per_mm=None, size_mm=None,
                        fitness=None if best is None else float(best.fitness),
                        generations=sum(s.ga.generation for _, s in islands), seconds=seconds,
                        confidence=0.0 if d is None else d.confidence, evaluations=evaluations, candidates=cands,
                        detection_score=None if d is None else d.score, contrast=None if d is None else d.contrast)
    d, best = results[0]
    return Estimate(found=True, position_mm=best.position_mm, rotation=best.R, alpha_px_per_mm=best.alpha,
                    size_mm=box_size_mm(model, best), alpha_xy_px_per_mm=best.alpha_xy, fitness=best.fitness,
                    generations=best.generations,
                    seconds=seconds, confidence=d.confidence, evaluations=evaluations,
                    candidates=cands, detection_score=d.score, contrast=d.contrast)


def box_size_mm(model: PhotoModel, c: Candidate) -> tuple[float, float]:
    """Real size (mm) of the candidate's model box: width along model x at alpha_x, height along
    model y at alpha_y (`Candidate.alpha_xy`)."""
    ax, ay = c.alpha_xy
    return (model.size_px[0] / ax, model.size_px[1] / ay)


def _candidate_json(c: Candidate, d: Detection, model: PhotoModel) -> dict:
    return {
        "found": bool(d.passed),
        "position_mm": [float(x) for x in c.position_mm],
        "rotation": [[float(x) for x in r] for r in c.R],
        "alpha_px_per_mm": float(c.alpha),
        "alpha_xy_px_per_mm": [float(x) for x in c.alpha_xy],
        "size_mm": [float(x) for x in box_size_mm(model, c)],
        "fitness": round(float(c.fitness), 6),
        "generations": int(c.generations),
        "detection_score": round(d.score, 6),
        "null_level": round(d.null_level, 6),
        "contrast": round(d.contrast, 6),
        "standing": round(d.standing, 6),
        "detection_threshold": round(d.threshold, 6),
        "outer_on_target": round(d.outer_on_target, 4),
        "appearance": round(d.appearance, 4) if np.isfinite(d.appearance) else None,
        "body_layout": round(d.body_layout, 4) if np.isfinite(d.body_layout) else None,
        "absent_parts": round(d.absent_parts, 4) if np.isfinite(d.absent_parts) else None,
        "bare_parts": int(d.bare_parts),
        "outline_judged": round(d.outline_judged, 4) if np.isfinite(d.outline_judged) else None,
        "off_water": round(d.off_water, 4) if np.isfinite(d.off_water) else None,
        "blob_beyond": round(d.blob_beyond, 4) if np.isfinite(d.blob_beyond) else None,
        "body_gap": round(d.body_gap, 2) if np.isfinite(d.body_gap) else None,
        "body_relief": round(d.body_relief, 4) if np.isfinite(d.body_relief) else None,
        "body_purity": round(d.body_purity, 4) if np.isfinite(d.body_purity) else None,
        "confidence": round(d.confidence, 4),
        "source": c.source,
    }
