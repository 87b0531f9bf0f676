"""The GA over poses (method steps 4-5): the 7 genes, their decoding into (R, t, alpha), the
convergence test and `PoseSearch`, one persistent GA population searching poses of a photo-model
against a stereo frame — an island of the acquisition (`vision/estimator.py`) or the tracker's
population (`vision/tracker.py`).

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

Tracking API (`PoseSearch`): `set_frame` for a new frame, `set_window` around a predicted pose,
`reset_full` to re-acquire, `seed` to inject poses, `step(n)`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Generator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, TypeVar

import numpy as np

from photoservo.geometry import (
    heading_tilt_from_rotation,
    rotation_from_heading_tilt,
)
from photoservo.vision.fitness import FitnessParams, StereoHue, fitness
from photoservo.vision.ga import GA, GAParams, Region
from photoservo.vision.photo_model import HUE_BINS, PhotoModel
from photoservo.vision.rig import Rig
from photoservo.vision.sampling import grey
from photoservo.vision.stereo_plane import align_to_plane, fit_target_plane
from photoservo.vision.twins import alternatives, turned_about_centroid

if TYPE_CHECKING:
    from photoservo.vision.estimator import EstimatorParams

T = TypeVar("T")

GENE_NAMES = {
    "image": ("u_px", "v_px", "q_per_m", "psi", "tilt_x", "tilt_y", "ln_s"),
    "cartesian": ("x_mm", "y_mm", "z_mm", "psi", "tilt_x", "tilt_y", "ln_alpha"),
}


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
        below min_apparent_px. Compiled (`genes_kernel.decode_genes`: the tracker decodes its
        population a few times a generation); `decode_reference` is the numpy version."""
        from photoservo.vision.genes_kernel import decode_genes

        g = np.ascontiguousarray(g, dtype=np.float64)
        if g.ndim == 1:
            g = g[None]
        P = len(g)
        R, t, alpha, valid = np.empty((P, 3, 3)), np.empty((P, 3)), np.empty(P), np.empty(P, np.bool_)
        decode_genes(g, self.kind == "image", math.radians(self.params.tilt_max_deg), *self._decode_constants,
                     R, t, alpha, valid)
        return R, t, alpha, valid

    @functools.cached_property
    def _decode_constants(self) -> tuple[np.ndarray, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """`decode_genes`'s rig and volume arguments: K, fx, limits, rig R and T, cams."""
        p, rig = self.params, self.rig
        limits = np.array([p.z_min_mm, p.z_max_mm, p.alpha_min, p.alpha_max,
                           self.fx * max(self.model.size_px) / p.min_apparent_px])
        cams = np.array([[c.K[0, 0], c.K[1, 1], c.K[0, 2], c.K[1, 2], c.width, c.height]
                         for c in (rig.left, rig.right)], dtype=np.float64)
        return (np.ascontiguousarray(rig.left.K, np.float64), self.fx, limits,
                np.ascontiguousarray(rig.R, np.float64), np.ascontiguousarray(rig.T, np.float64).reshape(3), cams)

    def decode_reference(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """`decode` in numpy (the reference the compiled kernel is tested against)."""
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
                    tilt_deg: float, alpha_frac: float, rng: np.random.Generator | None = None
                    ) -> Generator[int, None, Candidate]:
        """`local_search` one generation per step (see `steps`); `rng`: its own random stream
        (default: this search's)."""
        p = self.est_params
        short = dataclasses.replace(p, min_generations=max(1, p.patience // 2), patience=max(2, p.patience // 2),
                                    max_generations=max(p.patience, p.max_generations // 4))
        sub = PoseSearch(self.model, self.rig, self.frame, self.ga.params, short, self.fit_params, rng or self.ga.rng)
        sub.ga.reset(sub.space.window(R, t, alpha, position_mm=position_frac * float(t[2]), heading_deg=heading_deg,
                                      tilt_deg=tilt_deg, alpha_frac=alpha_frac))
        sub.seed(R, t, alpha)
        c = yield from sub.steps()
        self.ga.evaluations += sub.ga.evaluations
        self.ga.generation += c.generations
        return c

    def refine_aspect(self, best: Candidate, aspect_max: float) -> Candidate:
        """Per-axis size (the variable photo-model's alpha_x, alpha_y): a short GA of its own over
        the 7 pose genes in a narrow window around `best` plus an 8th, ln k in +- ln aspect_max,
        the photo's columns scaled by k and its rows by 1/k (`Candidate.aspect`). Returns the best
        of that search (its work counted in this search's generations and evaluations)."""
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
        ga = GA(f, region, self.ga.params, self.ga.rng, seeds=g0[None])
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
        lut = np.zeros(256, bool)
        lut[:HUE_BINS] = np.asarray(self.model.target_hues, bool)
        plane = fit_target_plane(best.R, best.position_mm, best.alpha, self.model, grey(left_bgr),
                                 grey(right_bgr), self.rig, on_target=lut[self.frame.left])
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
