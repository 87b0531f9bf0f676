"""The GA over poses (method steps 4-5): the convergence test and `PoseSearch`, one persistent GA
population searching poses of a photo-model against a stereo frame — an island of the acquisition (`vision/estimator.py`) or the tracker's
population (`vision/tracker.py`).

The genes and their decoding are `vision/genes.py` (`GeneSpace`).

Tracking API (`PoseSearch`): `set_frame` for a new frame, `set_window` around a predicted pose,
`reset_full` to re-acquire, `seed` to inject poses, `step(n)`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Generator
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeVar

import numpy as np

from photoservo.vision.fitness import FitnessParams, StereoHue, fitness, point_weight
from photoservo.vision.ga import GA, GAParams, Region
from photoservo.vision.genes import GeneSpace
from photoservo.vision.parts import foam_shares
from photoservo.vision.photo_model import PhotoModel
from photoservo.vision.rig import Rig
from photoservo.vision.sampling import grey
from photoservo.vision.stereo_plane import align_to_plane, fit_target_plane, on_target_hue
from photoservo.vision.twins import alternatives, turned_about_centroid

if TYPE_CHECKING:
    from photoservo.vision.estimator import EstimatorParams

T = TypeVar("T")

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

# ----------------------------------------------------------------------------- the search


@dataclass(frozen=True)
class Candidate:
    """One candidate pose: model in the left camera frame, R (3,3), position (3,) mm, alpha px/mm,
    and `aspect` k: the photo's two axes scaled apart (the "variable photo-model" for another
    individual's photo), a model point (u, v) px at (k u / alpha, v / (k alpha), 0) mm, i.e.
    alpha_x = alpha / k and alpha_y = alpha k (alpha stays their geometric mean)."""

    R: np.ndarray
    position_mm: np.ndarray
    alpha: float
    fitness: float
    generations: int
    source: str  # "blob 0", "blob 1", ..., "global"
    aspect: float = 1.0

    @property
    def alpha_xy(self) -> tuple[float, float]:
        """(alpha_x, alpha_y) px/mm along the photo's columns and rows."""
        return (self.alpha / self.aspect, self.alpha * self.aspect)

    @property
    def R_model(self) -> np.ndarray:
        """The linear part of the model-plane map handed to the fitness: R · diag(k, 1/k, 1), so
        that (R_model · (u/alpha, v/alpha, 0) + t) places the per-axis model (the kernel is
        unchanged: its R need not be a rotation)."""
        return aspect_map(self.R, np.array([self.aspect]))[0]


def aspect_map(R: np.ndarray, k: np.ndarray) -> np.ndarray:
    """R (P,3,3) or (3,3) with column 0 scaled by k and column 1 by 1/k, k (P,): see
    `Candidate.R_model`."""
    R = np.array(R, dtype=np.float64).reshape(-1, 3, 3)
    R[:, :, 0] *= k[:, None]
    R[:, :, 1] /= k[:, None]
    return R


class PoseSearch:
    """One GA searching poses of `model` against a stereo frame (method steps 4-5). The
    population persists: `set_frame` swaps the frame, `set_window` / `reset_full` the region,
    `seed` injects poses, `step(n)` advances n generations. Used by `estimate` (one per island)
    and by the tracking loop (one for the whole run). With `foam` (the pair's hue with its foam marked,
    `parts.foam_marked`) the GA scores each pose's inner points on foam as matches, one point's weight
    (`fitness.point_weight`) each, the cameras' mean, as `candidates.foam_neutral` weighs a fit (its
    candidates' `fitness` is so counted)."""

    def __init__(self, model: PhotoModel, rig: Rig, frame: StereoHue, ga_params: GAParams,
                 est_params: EstimatorParams, fit_params: FitnessParams, rng: np.random.Generator,
                 region: Region | None = None, foam: StereoHue | None = None) -> None:
        self.model, self.rig, self.frame, self.foam = model, rig, frame, foam
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
            if self.foam is not None:
                shares = foam_shares(R[valid], t[valid], alpha[valid], self.model, self.foam, self.rig)
                f[valid] += point_weight(self.model, self.fit_params) * len(self.model.inner_uv) * shares.mean(axis=1)
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
        best = drive(self.steps())
        return self.resolve_twins(best) if ambiguity_check else best

    def steps(self) -> Generator[int, None, Candidate]:
        """`run` without the ambiguity check, one generation per step: yields 1 after each
        generation (a caller may stop between any two and go on later: the tracker spreads an
        acquisition over camera frames, vision/tracker.py) and returns the best pose."""
        p = self.est_params
        conv = Convergence(p)
        for _ in range(p.max_generations):
            c = self.step(1)
            yield 1
            if conv.update(c.fitness, c.R, c.position_mm, c.alpha):
                break
        return self.best()

    def local_search(self, R: np.ndarray, t: np.ndarray, alpha: float, position_frac: float, heading_deg: float,
                     tilt_deg: float, alpha_frac: float) -> Candidate:
        """A short GA of its own (half the patience) in a narrow window around one pose, seeded
        with it; its work is counted in this search's generations and evaluations."""
        return drive(self.local_steps(R, t, alpha, position_frac, heading_deg, tilt_deg, alpha_frac))

    def local_steps(self, R: np.ndarray, t: np.ndarray, alpha: float, position_frac: float, heading_deg: float,
                    tilt_deg: float, alpha_frac: float, rng: np.random.Generator | None = None,
                    foam: StereoHue | None = None) -> Generator[int, None, Candidate]:
        """`local_search` one generation per step (see `steps`); `rng`: its own random stream
        (default: this search's); `foam`: its GA scores inner points on foam as matches (the class
        docstring; the result's `fitness` so counted)."""
        p = self.est_params
        short = dataclasses.replace(p, min_generations=max(1, p.patience // 2), patience=max(2, p.patience // 2),
                                    max_generations=max(p.patience, p.max_generations // 4))
        sub = PoseSearch(self.model, self.rig, self.frame, self.ga.params, short, self.fit_params, rng or self.ga.rng,
                         foam=foam)
        sub.ga.reset(sub.space.window(R, t, alpha, position_mm=position_frac * float(t[2]), heading_deg=heading_deg,
                                      tilt_deg=tilt_deg, alpha_frac=alpha_frac))
        sub.seed(R, t, alpha)
        c = yield from sub.steps()
        self.ga.evaluations += sub.ga.evaluations
        self.ga.generation += c.generations
        return c

    def refine_aspect(self, best: Candidate, aspect_max: float, rng: np.random.Generator | None = None) -> Candidate:
        """Per-axis size (the variable photo-model's alpha_x, alpha_y): a short GA of its own over
        the 7 pose genes in a narrow window around `best` plus an 8th, ln k in +- ln aspect_max,
        the photo's columns scaled by k and its rows by 1/k (`Candidate.aspect`). Returns the best
        of that search (its work counted in this search's generations and evaluations). `rng`: its
        own random stream (default: this search's)."""
        p = self.est_params
        short = dataclasses.replace(p, min_generations=max(1, p.patience // 2), patience=max(2, p.patience // 2),
                                    max_generations=max(p.patience, p.max_generations // 4))
        z = float(best.position_mm[2])
        win = self.space.window(best.R, best.position_mm, best.alpha, position_mm=0.02 * z, heading_deg=5.0,
                                tilt_deg=8.0, alpha_frac=0.12)
        b = math.log(aspect_max)
        region = Region.box(np.append(win.lo, -b), np.append(win.hi, b), np.append(win.periodic, False))

        def f(g: np.ndarray) -> np.ndarray:
            R, t, alpha, valid = self.space.decode(g[:, :7])
            out = np.full(len(g), -np.inf)
            if np.any(valid):
                Rk = aspect_map(R[valid], np.exp(0.5 * g[valid, 7]))
                out[valid] = fitness(Rk, t[valid], alpha[valid], self.model, self.frame, self.rig, self.fit_params)
            return out

        g0 = np.append(self.space.encode(best.R, best.position_mm, best.alpha)[0], math.log(best.aspect) * 2.0)
        ga = GA(f, region, self.ga.params, self.ga.rng if rng is None else rng, seeds=g0[None])
        conv = Convergence(short)
        for _ in range(short.max_generations):
            g, fit = ga.step(1)
            R, t, alpha, _ = self.space.decode(g[None, :7])
            if conv.update(fit, R[0], t[0], float(alpha[0])):
                break
        g, fit = ga.best()
        R, t, alpha, _ = self.space.decode(g[None, :7])
        self.ga.evaluations += ga.evaluations
        self.ga.generation += ga.generation
        return Candidate(R[0], t[0], float(alpha[0]), fit, self.ga.generation, best.source,
                         aspect=float(math.exp(0.5 * g[7])))

    def resolve_twins(self, best: Candidate) -> Candidate:
        """Try the look-alike twins of a converged pose (`alternatives`), each by a short GA in a
        narrow window around it; the best of the pose and its twins."""
        return drive(self.twin_steps(best))

    def twin_steps(self, best: Candidate) -> Generator[int, None, Candidate]:
        """`resolve_twins` one generation per step (see `steps`)."""
        if not np.isfinite(best.fitness):
            return best
        for R_alt in alternatives(best.R, best.position_mm):
            c = yield from self.local_steps(R_alt, best.position_mm, best.alpha, position_frac=0.03, heading_deg=15.0,
                                            tilt_deg=15.0, alpha_frac=0.08)
            if c.fitness > best.fitness:
                best = c
                self.ga.inject(self.space.encode(c.R, c.position_mm, c.alpha))
        return Candidate(best.R, best.position_mm, best.alpha, best.fitness, self.ga.generation, best.source)

    def grown_steps(self, best: Candidate, factors: tuple[float, ...],
                    min_gain: float = 0.0) -> Generator[int, None, Candidate]:
        """`best` scaled about its origin by each factor f in turn (alpha / f: the model f times as large
        at the same place; f = 1 refines it in place; each from the best so far), refined by a short GA
        in the twins' window; the best of them, one generation per step (see `steps`); a grown one (f != 1)
        only when it scores more than `min_gain` higher. Where the contour
        rule scores (vision/contour.py) the fitness peaks narrowly at the target's size, where its
        outline meets the edges, above broad ridges of fits shrunk inside the target (every inner point
        on it, edges found at an occluder) or grown past it: the island's GA settles on a ridge (the real
        pair's crate cut from the right image: 0.84 at 18-34 % too small; 0.90-0.91 at its size)."""
        source = best.source
        for f in factors:
            c = yield from self.local_steps(best.R, best.position_mm, best.alpha / f, position_frac=0.03,
                                            heading_deg=15.0, tilt_deg=15.0, alpha_frac=0.08)
            if c.fitness > best.fitness + (min_gain if f != 1.0 else 0.0):
                best = c
        return Candidate(best.R, best.position_mm, best.alpha, best.fitness, self.ga.generation, source)

    def turned_steps(self, best: Candidate, position_frac: float, alpha_frac: float, tilt_deg: float = 15.0,
                     rng: np.random.Generator | None = None) -> Generator[int, None, Candidate]:
        """The head-to-tail twin of `best` at the same place, one generation per step (see
        `steps`): turned about the photo mask's centroid (`turned_about_centroid`) and refined by a
        short GA in a window of position +- position_frac of the depth, heading +- 15 deg, tilt +- tilt_deg,
        alpha within (1 +- alpha_frac) (the twin's per-axis k is 1). The estimator lets the
        appearance cue choose between the candidate and its twin (`candidates.appearance_twin`), and keeps
        an island's twin that fits better (`candidates.turned_islands`). `rng`: the short GA's own random
        stream (default: this search's)."""
        R, t = turned_about_centroid(best.R, best.position_mm, best.alpha, self.model, best.aspect)
        c = yield from self.local_steps(R, t, best.alpha, position_frac=position_frac, heading_deg=15.0,
                                        tilt_deg=tilt_deg, alpha_frac=alpha_frac, rng=rng)
        return dataclasses.replace(c, source=best.source)

    def tilt_steps(self, best: Candidate, left_bgr: np.ndarray, right_bgr: np.ndarray, follow: bool = False,
                   rng: np.random.Generator | None = None) -> Generator[int, None, Candidate]:
        """Tilt from the disparity gradient (`vision/stereo_plane.py`), one generation per step (see
        `steps`): fit the target's plane from stereo over the inner points that land on target hue, turn
        the pose onto it (by theta), re-fit position, heading and scale by a short GA with the tilt held
        within 1.5 deg, and keep the result when its fitness is at most `plane_fitness_tol` below `best`
        (the hue fitness vetoes a plane fitted to the wrong thing); position +- 2 % of the depth, heading +- 5
        deg, alpha +- 5 %, with `follow` +- max(2 %, theta / 10), max(5 deg, theta), max(5 %, theta / 2): a fit
        tilted too little fits with heading and scale off (renderer 1019). `rng`: see `local_steps`."""
        plane = fit_target_plane(best.R, best.position_mm, best.alpha, self.model, grey(left_bgr),
                                 grey(right_bgr), self.rig, on_target=on_target_hue(self.model, self.frame.left))
        if plane is None:
            return best
        R2, t2 = align_to_plane(best.R, best.position_mm, plane)
        theta = math.acos(float(np.clip(best.R[:, 2] @ R2[:, 2], -1.0, 1.0))) if follow else 0.0
        c = yield from self.local_steps(R2, t2, best.alpha, position_frac=max(0.02, theta / 10),
                                        heading_deg=max(5.0, math.degrees(theta)), tilt_deg=1.5,
                                        alpha_frac=max(0.05, theta / 2), rng=rng)
        if c.fitness >= best.fitness - self.est_params.plane_fitness_tol:
            return Candidate(c.R, c.position_mm, c.alpha, c.fitness, self.ga.generation, best.source)
        return best


def drive(steps: Generator[int, None, T]) -> T:
    """Run a stepwise search (`PoseSearch.steps`, `estimator.acquisition`) to its end; its result."""
    while True:
        try:
            next(steps)
        except StopIteration as done:
            return done.value
