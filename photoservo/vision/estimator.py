"""Pose and size estimation from one stereo frame (method steps 3-5): the GA of `vision/ga.py`
searching the photo-model's pose and scale alpha against the stereo fitness of `vision/fitness.py`.

Genes. The paper's 7 genes are (x, y, z, three orientation parameters, alpha). By default
(`[estimator] genes = "image"`) the same 7 degrees of freedom are coded so that the search box
is the rig's field of view and the fitness landscape is nearly separable:

    g = (u, v, q, psi, tilt_x, tilt_y, ln s)

    u, v    px   where the model origin projects in the LEFT image (pinhole, no distortion)
    q       1/m  inverse depth, q = 1000 / z          (uniform in q = uniform in disparity)
    psi     rad  heading, tilt_x, tilt_y rad: tilt rotation vector (see `geometry.py`)
    ln s         s = fx / (alpha z): image px per photo px at a frontal pose

    t = z · K^-1 (u, v, 1),   alpha = fx / (s z),   R = R_tilt(tilt_x, tilt_y) · Rz(psi)

One image fixes (u, v, s) and the heading; the second camera fixes q through parallax — and with
it alpha: a big far model and a small near one agree in one camera, not in two (method step 3).
`genes = "cartesian"` is the paper's literal coding (x, y, z, psi, tilt_x, tilt_y, ln alpha).

Default search volume: the left image (u, v) with the origin also inside the right image, depth
z_min..z_max, any heading, tilt <= tilt_max, alpha_min..alpha_max and an apparent size of at
least `min_apparent_px`; candidates outside it score -inf.

Acquisition (`estimate`): the target's hues (the model's `target_hues`) are segmented in both
images; blobs are paired along the epipolar lines and triangulated, which gives (u, v, q), the
apparent scale s from the blob area and two heading hypotheses from the blob's principal axis.
Each pair seeds one GA island searching a window around it; an optional unseeded island
searches the whole volume. Every island stops when converged (`Convergence`), then tries the
pose's look-alike twins (planar-ambiguity mirror, heading + 180 deg). Each island's best is a
candidate, tested by `detect` (`Detection`: the fitness with the cameras combined by their
minimum — both must see it — against the threshold calibrated on empty and look-alike scenes in
benchmarks/accuracy.py, and the outline check: few outer points on target hue); the best passing
candidate is the estimate, the others the candidate list, and `found` is whether one passed.

Tracking (`PoseSearch`): one persistent GA; `set_frame` for a new frame, `set_window` around a
predicted pose, `reset_full` to re-acquire, `seed` to inject poses, `step(n)`.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.vision.fitness import (
    OUT_MISMATCH,
    FitnessParams,
    StereoHue,
    counts_reference,
    fitness,
    stereo_hue,
)
from photoservo.vision.ga import GA, GAParams, Region
from photoservo.vision.photo_model import HUE_BINS, PhotoModel
from photoservo.geometry import (
    heading_tilt_from_rotation,
    rotation_from_heading_tilt,
)
from photoservo.vision.rig import Rig
from photoservo.vision.stereo_plane import align_to_plane, fit_target_plane, grey

GENE_NAMES = {
    "image": ("u_px", "v_px", "q_per_m", "psi", "tilt_x", "tilt_y", "ln_s"),
    "cartesian": ("x_mm", "y_mm", "z_mm", "psi", "tilt_x", "tilt_y", "ln_alpha"),
}


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
    plane_refine: bool  # correct the tilt by a stereo plane fit over the inner points (vision/stereo_plane.py)
    plane_fitness_tol: float  # ...accepted when the re-fitted pose's fitness is at most this below the GA's
    min_generations: int  # never stop before this many generations
    max_generations: int  # always stop after this many generations
    patience: int  # converged: no improvement beyond the tolerances for this many generations
    fitness_tol: float  # ... best fitness rose by less than this
    position_tol_mm: float  # ... best position moved less than this (mm)
    rotation_tol_deg: float  # ... best rotation turned less than this (deg)
    alpha_tol: float  # ... best alpha changed by less than this fraction
    threshold: float  # detection threshold (found = detection_score >= threshold)
    max_outer_on_target: float  # detection also needs at most this share of outer points on target hue
    confidence_scale: float  # width of the logistic confidence around the threshold

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


# ----------------------------------------------------------------------------- gene spaces


@dataclass(frozen=True)
class GeneSpace:
    """Decodes genes (P, 7) into poses for one rig and photo-model (module docstring)."""

    kind: Literal["image", "cartesian"]
    rig: Rig
    model: PhotoModel
    params: EstimatorParams

    @property
    def fx(self) -> float:
        return float(self.rig.left.K[0, 0])

    def decode(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Genes (P, 7) -> (R (P,3,3), t (P,3) mm, alpha (P,) px/mm, valid (P,) bool).
        Tilt beyond tilt_max is clamped onto it; `valid` is False outside the search volume:
        depth or alpha out of range, model origin outside either image (pinhole), apparent size
        below min_apparent_px. (Called once per generation: kept to few numpy operations.)"""
        g = np.asarray(g, dtype=np.float64)
        if g.ndim == 1:
            g = g[None]
        p, K, rig = self.params, self.rig.left.K, self.rig
        tmax = math.radians(p.tilt_max_deg)
        tx, ty = g[:, 4], g[:, 5]
        th2 = tx * tx + ty * ty
        if np.any(th2 > tmax * tmax):
            shrink = np.minimum(1.0, tmax / np.sqrt(np.maximum(th2, 1e-24)))
            tx, ty = tx * shrink, ty * shrink
        R = rotation_from_heading_tilt(g[:, 3], tx, ty)
        t = np.empty((len(g), 3))
        if self.kind == "image":
            z = 1000.0 / g[:, 2]
            t[:, 0] = (g[:, 0] - K[0, 2]) * (z / K[0, 0])
            t[:, 1] = (g[:, 1] - K[1, 2]) * (z / K[1, 1])
            t[:, 2] = z
            alpha = self.fx / (np.exp(g[:, 6]) * z)
        else:
            t[:] = g[:, :3]
            z = t[:, 2]
            alpha = np.exp(g[:, 6])
        valid = (z >= p.z_min_mm * 0.999) & (z <= p.z_max_mm * 1.001)
        valid &= (alpha >= p.alpha_min * 0.999) & (alpha <= p.alpha_max * 1.001)
        # apparent size (longest side of the target in the image at a frontal pose)
        valid &= alpha * z <= self.fx * max(self.model.size_px) / p.min_apparent_px
        # the model origin must be seen by both cameras
        with np.errstate(divide="ignore", invalid="ignore"):
            for cam, X in ((rig.left, t), (rig.right, t @ rig.R.T + rig.T)):
                w = 1.0 / X[:, 2]
                uc = X[:, 0] * w * cam.K[0, 0] + cam.K[0, 2]
                vc = X[:, 1] * w * cam.K[1, 1] + cam.K[1, 2]
                valid &= (w > 0) & (uc >= -0.5) & (uc <= cam.width - 0.5) & (vc >= -0.5) & (vc <= cam.height - 0.5)
        return R, t, alpha, valid

    def encode(self, R: np.ndarray, t: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        """Poses -> genes (P, 7), the inverse of `decode` (tilt not clamped)."""
        R = np.asarray(R, dtype=np.float64).reshape(-1, 3, 3)
        t = np.asarray(t, dtype=np.float64).reshape(-1, 3)
        alpha = np.asarray(alpha, dtype=np.float64).reshape(-1)
        psi, tx, ty = heading_tilt_from_rotation(R)
        if self.kind == "image":
            K = self.rig.left.K
            z = t[:, 2]
            u = K[0, 0] * t[:, 0] / z + K[0, 2]
            v = K[1, 1] * t[:, 1] / z + K[1, 2]
            return np.column_stack([u, v, 1000.0 / z, psi, tx, ty, np.log(self.fx / (alpha * z))])
        return np.column_stack([t, psi, tx, ty, np.log(alpha)])

    def full_region(self) -> Region:
        """The default search volume as a gene box (module docstring)."""
        p, cam = self.params, self.rig.left
        tmax = math.radians(p.tilt_max_deg)
        if self.kind == "image":
            # apparent scale s = fx / (alpha z): from the smallest apparent size to the largest s
            # any (alpha, z) of the volume allows, capped at 3x the image width
            longest = max(self.model.size_px)
            s_lo = p.min_apparent_px / longest
            s_hi = min(self.fx / (p.alpha_min * p.z_min_mm), 3.0 * cam.width / longest)
            s_lo = max(s_lo, self.fx / (p.alpha_max * p.z_max_mm))
            lo = [-0.5, -0.5, 1000.0 / p.z_max_mm, -math.pi, -tmax, -tmax, math.log(s_lo)]
            hi = [cam.width - 0.5, cam.height - 0.5, 1000.0 / p.z_min_mm, math.pi, tmax, tmax,
                  math.log(max(s_hi, s_lo * 1.01))]
        else:
            half_w = p.z_max_mm * max(cam.K[0, 2] + 0.5, cam.width - cam.K[0, 2]) / cam.K[0, 0]
            half_h = p.z_max_mm * max(cam.K[1, 2] + 0.5, cam.height - cam.K[1, 2]) / cam.K[1, 1]
            lo = [-half_w, -half_h, p.z_min_mm, -math.pi, -tmax, -tmax, math.log(p.alpha_min)]
            hi = [half_w, half_h, p.z_max_mm, math.pi, tmax, tmax, math.log(p.alpha_max)]
        return Region.box(lo, hi, [False, False, False, True, False, False, False])

    def window(self, R: np.ndarray, t: np.ndarray, alpha: float, position_mm: float,
               heading_deg: float, tilt_deg: float, alpha_frac: float) -> Region:
        """A gene box around one pose: position +- position_mm (converted to image px and inverse
        depth for the image coding), heading +- heading_deg (>= 180: any), tilt +- tilt_deg,
        alpha within a factor (1 +- alpha_frac). Clipped to the full volume."""
        g0 = self.encode(R, t, alpha)[0]
        full = self.full_region()
        z = float(np.asarray(t).reshape(3)[2])
        tw = math.radians(tilt_deg)
        la = math.log1p(alpha_frac)
        if self.kind == "image":
            du = self.rig.left.K[0, 0] * position_mm / z
            dv = self.rig.left.K[1, 1] * position_mm / z
            dq = 1000.0 / max(z - position_mm, 1e-3) - 1000.0 / z
            half = np.array([du, dv, dq, 0.0, tw, tw, la])
        else:
            half = np.array([position_mm, position_mm, position_mm, 0.0, tw, tw, la])
        lo, hi = g0 - half, g0 + half
        periodic = np.zeros(7, bool)
        if heading_deg >= 180:
            lo[3], hi[3], periodic[3] = -math.pi, math.pi, True
        else:
            lo[3], hi[3] = g0[3] - math.radians(heading_deg), g0[3] + math.radians(heading_deg)
        keep = ~periodic
        keep[3] = False
        lo[keep] = np.maximum(lo[keep], full.lo[keep])
        hi[keep] = np.minimum(hi[keep], full.hi[keep])
        hi = np.maximum(hi, lo + 1e-9)
        return Region.box(lo, hi, periodic)


# ----------------------------------------------------------------------------- convergence


class Convergence:
    """Converged (method step 4, our definition): over the last `patience` generations the best
    individual's fitness rose by less than `fitness_tol`, its position moved less than
    `position_tol_mm`, its rotation turned less than `rotation_tol_deg` and its alpha changed by
    less than the fraction `alpha_tol` — and at least `min_generations` generations ran."""

    def __init__(self, params: EstimatorParams) -> None:
        self.p = params
        self.history: list[tuple[float, np.ndarray, np.ndarray, float]] = []

    def update(self, f: float, R: np.ndarray, t: np.ndarray, alpha: float) -> bool:
        """Record generation's best; True when converged."""
        self.history.append((f, R, t, alpha))
        n = len(self.history)
        p = self.p
        if n <= max(p.patience, p.min_generations):
            return False
        f0, R0, t0, a0 = self.history[-1 - p.patience]
        if not np.isfinite(f) or f - f0 > p.fitness_tol:
            return False
        if np.linalg.norm(t - t0) > p.position_tol_mm:
            return False
        c = np.clip((np.trace(R0.T @ R) - 1.0) / 2.0, -1.0, 1.0)
        if math.degrees(math.acos(c)) > p.rotation_tol_deg:
            return False
        return abs(alpha / a0 - 1.0) <= p.alpha_tol


# ----------------------------------------------------------------------------- estimate


@dataclass(frozen=True)
class Candidate:
    """One candidate pose: model in the left camera frame, R (3,3), position (3,) mm, alpha px/mm."""

    R: np.ndarray
    position_mm: np.ndarray
    alpha: float
    fitness: float
    generations: int
    source: str  # "blob 0", "blob 1", ..., "global"


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
            "size_mm": lst(self.size_mm),
            "fitness": None if self.fitness is None else round(float(self.fitness), 6),
            "generations": int(self.generations),
            "seconds": round(float(self.seconds), 4),
            "confidence": round(float(self.confidence), 4),
            "detection_score": None if self.detection_score is None else round(float(self.detection_score), 6),
            "evaluations": int(self.evaluations),
        }
        if with_candidates:
            out["candidates"] = list(self.candidates)
        return out


class PoseSearch:
    """One GA searching poses of `model` against a stereo frame (method steps 4-5). The
    population persists: `set_frame` swaps the frame, `set_window` / `reset_full` the region,
    `seed` injects poses, `step(n)` advances n generations. Used by `estimate` (one per island)
    and by the tracking loop (one for the whole run)."""

    def __init__(self, model: PhotoModel, rig: Rig, frame: StereoHue, ga_params: GAParams,
                 est_params: EstimatorParams, fit_params: FitnessParams, rng: np.random.Generator,
                 region: Region | None = None) -> None:
        self.model, self.rig, self.frame = model, rig, frame
        self.fit_params, self.est_params = fit_params, est_params
        self.space = GeneSpace(est_params.genes, rig, model, est_params)
        self.ga = GA(self._fitness, region or self.space.full_region(), ga_params, rng)
        self._best_cache: tuple[np.ndarray, np.ndarray, np.ndarray, float] | None = None

    def _fitness(self, g: np.ndarray) -> np.ndarray:
        R, t, alpha, valid = self.space.decode(g)
        f = np.full(len(g), -np.inf)
        if np.any(valid):
            f[valid] = fitness(R[valid], t[valid], alpha[valid], self.model, self.frame, self.rig,
                               self.fit_params)
        return f

    def set_frame(self, frame: StereoHue) -> None:
        """A new stereo frame; the population is re-scored on it."""
        self.frame = frame
        self.ga.set_fitness(self._fitness)

    def set_window(self, R: np.ndarray, t: np.ndarray, alpha: float, position_mm: float,
                   heading_deg: float, tilt_deg: float, alpha_frac: float) -> None:
        """Search a window around a predicted pose (see `GeneSpace.window`)."""
        self.ga.set_region(self.space.window(R, t, alpha, position_mm, heading_deg, tilt_deg, alpha_frac))

    def reset_full(self) -> None:
        """Back to the whole search volume with a fresh population (re-acquisition)."""
        self.ga.reset(self.space.full_region())

    def seed(self, R: np.ndarray, t: np.ndarray, alpha: np.ndarray) -> None:
        """Inject poses (model in left camera frame) into the population."""
        self.ga.inject(self.space.encode(R, t, alpha))

    def step(self, generations: int = 1) -> Candidate:
        """Advance `generations` generations; the best pose so far."""
        self.ga.step(generations)
        return self.best()

    def best(self, source: str = "") -> Candidate:
        """The best individual decoded (the decoding is cached while the best genes stay put)."""
        g, f = self.ga.best()
        if self._best_cache is None or not np.array_equal(self._best_cache[0], g):
            R, t, alpha, _ = self.space.decode(g)
            self._best_cache = (g, R[0], t[0], float(alpha[0]))
        _, R, t, alpha = self._best_cache
        return Candidate(R=R, position_mm=t, alpha=alpha, fitness=f, generations=self.ga.generation, source=source)

    def run(self, ambiguity_check: bool = True) -> Candidate:
        """Evolve until converged (`Convergence`) or max_generations; the best pose.

        With `ambiguity_check`, the converged pose's look-alike twins are then tried, each by a
        short GA of its own in a narrow window around it (`alternatives`): the mirror of the
        planar pose ambiguity (normal reflected about the line of sight), the heading turned by
        180 degrees, and both. A twin that scores higher replaces the pose."""
        p = self.est_params
        conv = Convergence(p)
        for _ in range(p.max_generations):
            c = self.step(1)
            if conv.update(c.fitness, c.R, c.position_mm, c.alpha):
                break
        best = self.best()
        return self.resolve_twins(best) if ambiguity_check else best

    def local_search(self, R: np.ndarray, t: np.ndarray, alpha: float, position_frac: float, heading_deg: float,
                     tilt_deg: float, alpha_frac: float) -> Candidate:
        """A short GA of its own (half the patience) in a narrow window around one pose, seeded
        with it; its work is counted in this search's generations and evaluations."""
        p = self.est_params
        short = dataclasses.replace(p, min_generations=max(1, p.patience // 2), patience=max(2, p.patience // 2),
                                    max_generations=max(p.patience, p.max_generations // 4))
        sub = PoseSearch(self.model, self.rig, self.frame, self.ga.params, short, self.fit_params, self.ga.rng)
        sub.ga.reset(sub.space.window(R, t, alpha, position_mm=position_frac * float(t[2]), heading_deg=heading_deg,
                                      tilt_deg=tilt_deg, alpha_frac=alpha_frac))
        sub.seed(R, t, alpha)
        c = sub.run(ambiguity_check=False)
        self.ga.evaluations += sub.ga.evaluations
        self.ga.generation += c.generations
        return c

    def resolve_twins(self, best: Candidate) -> Candidate:
        """Try the look-alike twins of a converged pose (`alternatives`), each by a short GA in a
        narrow window around it; the best of the pose and its twins."""
        if not np.isfinite(best.fitness):
            return best
        for R_alt in alternatives(best.R, best.position_mm):
            c = self.local_search(R_alt, best.position_mm, best.alpha, position_frac=0.03, heading_deg=15.0,
                                  tilt_deg=15.0, alpha_frac=0.08)
            if c.fitness > best.fitness:
                best = c
                self.ga.inject(self.space.encode(c.R, c.position_mm, c.alpha))
        return Candidate(best.R, best.position_mm, best.alpha, best.fitness, self.ga.generation, best.source)

    def refine_tilt(self, best: Candidate, left_bgr: np.ndarray, right_bgr: np.ndarray) -> Candidate:
        """Tilt from the disparity gradient (`vision/stereo_plane.py`): fit the target's plane
        from stereo over the inner points that land on target hue, turn the pose onto it, re-fit
        position, heading and scale by a short GA with the tilt held within 1.5 deg, and keep the
        result when its fitness is at most `plane_fitness_tol` below `best` (the hue fitness
        vetoes a plane fitted to the wrong thing)."""
        lut = np.zeros(256, bool)
        lut[:HUE_BINS] = np.asarray(self.model.target_hues, bool)
        plane = fit_target_plane(best.R, best.position_mm, best.alpha, self.model, grey(left_bgr),
                                 grey(right_bgr), self.rig, on_target=lut[self.frame.left])
        if plane is None:
            return best
        R2, t2 = align_to_plane(best.R, best.position_mm, plane)
        c = self.local_search(R2, t2, best.alpha, position_frac=0.02, heading_deg=5.0, tilt_deg=1.5, alpha_frac=0.05)
        if c.fitness >= best.fitness - self.est_params.plane_fitness_tol:
            return Candidate(c.R, c.position_mm, c.alpha, c.fitness, self.ga.generation, best.source)
        return best


def alternatives(R: np.ndarray, t: np.ndarray) -> list[np.ndarray]:
    """Orientations a flat target's pose is easily confused with (see `PoseSearch.run`): the
    planar-ambiguity mirror, the heading turned by 180 degrees about the model normal, and both."""
    half_turn = np.diag([-1.0, -1.0, 1.0])  # Rz(pi): heading + 180 deg
    R_m = reflected_rotation(R, t)
    return [R_m, R @ half_turn, R_m @ half_turn]


def reflected_rotation(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The other solution of the planar pose ambiguity: a flat target seen along the ray d = t/|t|
    looks nearly alike with its normal n and with n' = 2 (n·d) d - n (the normal mirrored about
    the line of sight). Returns R' = Rot(n -> n') · R, the smallest turn taking n to n'."""
    d = np.asarray(t, dtype=np.float64) / np.linalg.norm(t)
    n = R[:, 2]
    n2 = 2.0 * (n @ d) * d - n
    axis = np.cross(n, n2)
    s = np.linalg.norm(axis)
    if s < 1e-12:
        return R.copy()
    ang = math.atan2(s, float(n @ n2))
    rvec = axis / s * ang
    return cv2.Rodrigues(rvec)[0] @ R


# --- seeding from target-hue blobs


@dataclass(frozen=True)
class Blob:
    """A connected region of target hue in one image: centroid (u, v) px, area px, major-axis
    angle (rad, image x toward y) and elongation (major / minor axis)."""

    centroid: np.ndarray
    area: float
    angle: float
    elongation: float


def _moments_shape(m: dict) -> tuple[np.ndarray, float, float, float]:
    a = m["m00"]
    c = np.array([m["m10"] / a, m["m01"] / a])
    mu20, mu02, mu11 = m["mu20"] / a, m["mu02"] / a, m["mu11"] / a
    angle = 0.5 * math.atan2(2 * mu11, mu20 - mu02)
    d = math.sqrt(max(0.0, 4 * mu11 * mu11 + (mu20 - mu02) ** 2))
    l1, l2 = (mu20 + mu02 + d) / 2, (mu20 + mu02 - d) / 2
    return c, a, angle, math.sqrt(l1 / max(l2, 1e-9))


def target_blobs(hue: np.ndarray, target_hues: np.ndarray, min_px: int, max_blobs: int = 12,
                 merge_px: int = 9) -> list[Blob]:
    """Blobs of the model's target hues in a hue image (largest first). Pieces closer than about
    `merge_px` (a creature cut up by foam, glints or its own markings) count as one blob; its
    area and moments are those of the target-hue pixels only."""
    lut = np.zeros(256, np.uint8)
    lut[:HUE_BINS] = np.asarray(target_hues, bool) * 255
    mask = cv2.morphologyEx(lut[hue], cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5)))
    grouped = cv2.dilate(mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (merge_px, merge_px)))
    _, labels, stats, _ = cv2.connectedComponentsWithStats(grouped, connectivity=8)
    labels[mask == 0] = 0
    area = np.bincount(labels.ravel(), minlength=len(stats)).astype(float)
    order = [i for i in np.argsort(-area, kind="stable") if i > 0 and area[i] >= min_px]
    blobs = []
    for i in order[:max_blobs]:
        x, y, w, h = stats[i, :4]
        m = cv2.moments((labels[y:y + h, x:x + w] == i).astype(np.uint8), binaryImage=True)
        c, a, ang, el = _moments_shape(m)
        blobs.append(Blob(centroid=c + (x, y), area=a, angle=ang, elongation=el))
    return blobs


@dataclass(frozen=True)
class BlobPair:
    """A left and a right blob matched along the epipolar line, triangulated: origin guess in
    the left camera frame (mm), the left blob, the epipolar residual (px)."""

    position_mm: np.ndarray
    left: Blob
    right: Blob
    residual_px: float


def match_blobs(left: list[Blob], right: list[Blob], rig: Rig, params: EstimatorParams) -> list[BlobPair]:
    """Pair blobs whose centroids lie on each other's epipolar lines (within epipolar_tol_px plus
    a share of the blob size), whose triangulated depth is in the search volume and whose areas
    agree within 2.5x; each left blob takes its best right blob. Largest first."""
    if not left or not right:
        return []
    def norm(blobs: list[Blob], cam) -> np.ndarray:
        pts = np.array([b.centroid for b in blobs], np.float64).reshape(-1, 1, 2)
        return cv2.undistortPoints(pts, cam.K, cam.dist).reshape(-1, 2)
    nl, nr = norm(left, rig.left), norm(right, rig.right)
    R, T = rig.R, rig.T
    tx = np.array([[0, -T[2], T[1]], [T[2], 0, -T[0]], [-T[1], T[0], 0]])
    E = tx @ R  # x_r^T E x_l = 0
    f = float(rig.right.K[0, 0])
    pairs = []
    for i, bl in enumerate(left):
        xl = np.array([nl[i, 0], nl[i, 1], 1.0])
        line = E @ xl
        best = None
        for j, br in enumerate(right):
            if not (1 / 2.5 <= br.area / bl.area <= 2.5):
                continue
            xr = np.array([nr[j, 0], nr[j, 1], 1.0])
            err = abs(line @ xr) / max(math.hypot(line[0], line[1]), 1e-12) * f
            if err > params.epipolar_tol_px + 0.15 * math.sqrt(min(bl.area, br.area)):
                continue
            # depth along the left ray: least squares of  z_l R xl + T = z_r xr
            A = np.column_stack([R @ xl, -xr])
            (zl, zr), *_ = np.linalg.lstsq(A, -T, rcond=None)
            if not (params.z_min_mm <= zl <= params.z_max_mm) or zr <= 0:
                continue
            if best is None or err < best[0]:
                best = (err, zl * xl, br)
        if best is not None:
            pairs.append(BlobPair(position_mm=best[1], left=bl, right=best[2], residual_px=best[0]))
    return pairs


@dataclass(frozen=True)
class ModelShape:
    """Area (photo px), centroid offset from the model origin (px) and principal axis of the
    photo-model's target mask — what a blob is compared with."""

    area: float
    centroid_uv: np.ndarray
    angle: float
    elongation: float

    @staticmethod
    def of(model: PhotoModel) -> ModelShape:
        m = cv2.moments((np.asarray(model.mask) > 0).astype(np.uint8), binaryImage=True)
        c, a, ang, el = _moments_shape(m)
        return ModelShape(area=a, centroid_uv=c - np.asarray(model.origin_px), angle=ang, elongation=el)


def seed_genes(pair: BlobPair, shape: ModelShape, space: GeneSpace, rng: np.random.Generator,
               n: int) -> tuple[np.ndarray, Region]:
    """Seed individuals (n, 7) and the island's window for one blob pair (image coding).

    Apparent scale s from the blob area (s^2 = area_blob / area_model; a tilt shrinks the blob,
    so the window reaches further up than down), headings psi from the difference of principal
    axes (two hypotheses, 180 deg apart; random when either shape is nearly round), origin = blob
    centroid minus the rotated, scaled centroid offset of the photo mask."""
    p = space.params
    full = space.full_region()
    K = space.rig.left.K
    X = pair.position_mm
    z = float(X[2])
    s0 = math.sqrt(pair.left.area / shape.area)
    ls0 = math.log(s0)
    q0 = 1000.0 / z
    if pair.left.elongation > 1.25 and shape.elongation > 1.25:
        base = pair.left.angle - shape.angle
        psis = np.array([base, base + math.pi])
    else:
        psis = rng.uniform(-math.pi, math.pi, 2)
    cu = K[0, 0] * X[0] / z + K[0, 2]
    cv = K[1, 1] * X[1] / z + K[1, 2]
    r_img = math.sqrt(pair.left.area / math.pi)
    half_uv = 4.0 + 0.35 * r_img
    lo = np.array([cu - half_uv - s0 * np.abs(shape.centroid_uv).max(), 0, q0 * (1 - p.window_depth), 0, 0, 0,
                   ls0 - 0.5 * p.window_scale])
    hi = np.array([cu + half_uv + s0 * np.abs(shape.centroid_uv).max(), 0, q0 * (1 + p.window_depth), 0, 0, 0,
                   ls0 + p.window_scale])
    lo[1] = cv - half_uv - s0 * np.abs(shape.centroid_uv).max()
    hi[1] = cv + half_uv + s0 * np.abs(shape.centroid_uv).max()
    lo[3:6], hi[3:6] = full.lo[3:6], full.hi[3:6]
    lo = np.maximum(lo, full.lo)
    hi = np.minimum(hi, full.hi)
    hi = np.maximum(hi, lo + 1e-6)
    region = Region.box(lo, hi, full.periodic)
    seeds = region.sample(rng, n)
    k = np.arange(n)
    psi = psis[k % 2] + rng.normal(0, 0.15, n)
    off = np.stack([np.cos(psi) * shape.centroid_uv[0] - np.sin(psi) * shape.centroid_uv[1],
                    np.sin(psi) * shape.centroid_uv[0] + np.cos(psi) * shape.centroid_uv[1]], 1) * s0
    seeds[:, 0] = cu - off[:, 0] + rng.normal(0, 1.0, n)
    seeds[:, 1] = cv - off[:, 1] + rng.normal(0, 1.0, n)
    seeds[:, 2] = q0 * (1 + rng.normal(0, 0.02, n))
    seeds[:, 3] = psi
    tilt = rng.uniform(0, 1, n) ** 0.5 * math.radians(min(p.tilt_max_deg, 35.0))
    phi = rng.uniform(-math.pi, math.pi, n)
    tilt[: max(1, n // 4)] = 0.0
    seeds[:, 4], seeds[:, 5] = tilt * np.cos(phi), tilt * np.sin(phi)
    # the blob may be a fragment of the creature (foam, glints): scales up to x1.5 are as likely
    seeds[:, 6] = ls0 + rng.uniform(-0.1, 0.4, n)
    return region.repair(seeds), region


def confidence(f: float, params: EstimatorParams) -> float:
    """Logistic confidence that a candidate of fitness f is the target."""
    if not np.isfinite(f):
        return 0.0
    return 1.0 / (1.0 + math.exp(-(f - params.threshold) / params.confidence_scale))


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
    frame = frame or stereo_hue(left_bgr, right_bgr, fit_params)
    ss = np.random.SeedSequence(seed)
    p = est_params
    islands: list[tuple[str, PoseSearch]] = []
    if p.seeding and p.genes == "image":
        bl = target_blobs(frame.left, model.target_hues, p.min_blob_px)
        br = target_blobs(frame.right, model.target_hues, p.min_blob_px)
        pairs = match_blobs(bl, br, rig, p)[: p.max_candidates]
        shape = ModelShape.of(model)
        for i, (pair, s) in enumerate(zip(pairs, ss.spawn(len(pairs)))):
            rng = np.random.default_rng(s)
            search = PoseSearch(model, rig, frame, ga_params, p, fit_params, rng)
            seeds, region = seed_genes(pair, shape, search.space, rng, ga_params.population)
            search.ga.set_region(region)
            search.ga.genes[:] = seeds
            islands.append((f"blob {i}", search))
    if p.global_island or not islands:
        rng = np.random.default_rng(ss.spawn(1)[0])
        islands.append(("global", PoseSearch(model, rig, frame, ga_params, p, fit_params, rng)))
    results = []
    evaluations = 0
    firsts = [search.run(ambiguity_check=False) for _, search in islands]
    # the look-alike twins (mirror, heading + 180 deg) are tried for the leading island only
    lead = int(np.argmax([c.fitness for c in firsts]))
    firsts[lead] = islands[lead][1].resolve_twins(firsts[lead])
    if p.plane_refine and np.isfinite(firsts[lead].fitness):
        firsts[lead] = islands[lead][1].refine_tilt(firsts[lead], left_bgr, right_bgr)
    for (name, search), c in zip(islands, firsts):
        evaluations += search.ga.evaluations
        if np.isfinite(c.fitness):
            results.append((detect(c, model, frame, rig, fit_params, p),
                            Candidate(c.R, c.position_mm, c.alpha, c.fitness, c.generations, name)))
    results.sort(key=lambda dc: (-dc[0].passed, -dc[0].score, -dc[1].fitness))
    cands = tuple(_candidate_json(c, d, model) for d, c in results)
    seconds = time.perf_counter() - t0
    if not results or not results[0][0].passed:
        d, best = results[0] if results else (None, None)
        return Estimate(found=False, position_mm=None, rotation=None, alpha_px_per_mm=None, size_mm=None,
                        fitness=None if best is None else float(best.fitness),
                        generations=sum(s.ga.generation for _, s in islands), seconds=seconds,
                        confidence=0.0 if d is None else d.confidence, evaluations=evaluations, candidates=cands,
                        detection_score=None if d is None else d.score)
    d, best = results[0]
    return Estimate(found=True, position_mm=best.position_mm, rotation=best.R, alpha_px_per_mm=best.alpha,
                    size_mm=model.size_mm(best.alpha), fitness=best.fitness, generations=best.generations,
                    seconds=seconds, confidence=d.confidence, evaluations=evaluations,
                    candidates=cands, detection_score=d.score)


@dataclass(frozen=True)
class Detection:
    """Is a candidate the target? `score`: the stereo fitness with the two cameras combined by
    their minimum (`[fitness] combine = "min"`), so a look-alike seen by one camera only, or a
    pose that fits one image and not the other, cannot pass on the strength of one camera (the GA
    itself optimises the configured combination). `outer_on_target`: the largest share, over the
    two cameras, of outer points S_out landing on target hue — the creature's outline must end
    where the model's does (a buoy or another species of the same colour usually spills over).
    passed = score >= threshold and outer_on_target <= max_outer_on_target;
    confidence = logistic((score - threshold) / confidence_scale)
                 · logistic((max_outer_on_target - outer_on_target) / 0.02)."""

    score: float
    outer_on_target: float
    passed: bool
    confidence: float


def detect(c: Candidate, model: PhotoModel, frame: StereoHue, rig: Rig, fit_params: FitnessParams,
           p: EstimatorParams) -> Detection:
    """The detection test of one candidate (see `Detection`)."""
    strict = dataclasses.replace(fit_params, combine="min")
    score = float(fitness(c.R, c.position_mm, c.alpha, model, frame, rig, strict)[0])
    counts = counts_reference(c.R, c.position_mm, c.alpha, model, frame, rig, fit_params)[0]
    outer = float(counts[:, OUT_MISMATCH].max()) / max(1, len(model.outer_uv))
    passed = score >= p.threshold and outer <= p.max_outer_on_target
    conf = confidence(score, p) / (1.0 + math.exp(-(p.max_outer_on_target - outer) / 0.02))
    return Detection(score=score, outer_on_target=outer, passed=bool(passed), confidence=conf)


def _candidate_json(c: Candidate, d: Detection, model: PhotoModel) -> dict:
    return {
        "found": bool(d.passed),
        "position_mm": [float(x) for x in c.position_mm],
        "rotation": [[float(x) for x in r] for r in c.R],
        "alpha_px_per_mm": float(c.alpha),
        "size_mm": [float(x) for x in model.size_mm(c.alpha)],
        "fitness": round(float(c.fitness), 6),
        "generations": int(c.generations),
        "detection_score": round(d.score, 6),
        "outer_on_target": round(d.outer_on_target, 4),
        "confidence": round(d.confidence, 4),
        "source": c.source,
    }
