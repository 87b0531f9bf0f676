"""The genetic algorithm of method step 4 (and step 5, the real-time multi-step GA).

The GA maximises a fitness over a box of genes. It knows nothing about poses: the estimator
(`vision/estimator.py`) chooses the 7 genes and decodes them into (R, t, alpha). The population
persists between calls to `step(generations)`, so the tracking loop can advance it a few
generations per video frame; the search region can be replaced (a window around a predicted pose,
or the full volume to re-acquire) and individuals injected (seeding).

Two codings share selection, elitism and the population bookkeeping:

* ``"binary"`` — the paper's reference: each individual is a 68-bit chromosome, plain binary
  (not Gray), genes in this order and with these bit counts (`PAPER_BITS`)::

      bits  1-10  gene 0  (x, or the image column u)            10 bits
      bits 11-20  gene 1  (y, or the image row v)               10 bits
      bits 21-30  gene 2  (z, or the inverse depth)             10 bits
      bits 31-40  gene 3  heading psi                           10 bits
      bits 41-49  gene 4  tilt_x                                 9 bits
      bits 50-58  gene 5  tilt_y                                 9 bits
      bits 59-68  gene 6  alpha on a log scale (or log s)       10 bits

  A gene with b bits takes the 2**b values lo + k (hi - lo) / (2**b - 1) of its region
  (periodic genes: lo + k (hi - lo) / 2**b). Crossover is two-point on the whole string,
  mutation flips each bit with probability `mutation`.

* ``"real"`` — real-coded genes (the default; it converges faster and more reliably, see
  benchmarks/accuracy.py): BLX-a blend crossover, Gaussian mutation whose step size is
  self-adapted per individual (log-normal, as in evolution strategies), and a share of the
  children made by mutating the current best individual (local refinement).

Both: tournament selection, `elite` best individuals copied unchanged into the next generation.
The fitness is called once per generation with the whole population (P, D) -> (P,).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from photoservo.errors import InputError

PAPER_BITS: tuple[int, ...] = (10, 10, 10, 10, 9, 9, 10)  # 68 bits (see module docstring)

FitnessFn = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class GAParams:
    """[ga] config: the genetic algorithm's own settings."""

    coding: Literal["real", "binary"]  # gene coding (binary = the paper's 68-bit chromosome)
    population: int  # individuals
    elite: int  # best individuals copied unchanged into the next generation
    tournament: int  # tournament size of the parent selection
    crossover: float  # probability that a child is made by crossover (else a parent's copy)
    mutation: float  # real: per-gene mutation probability; binary: per-bit flip probability
    sigma: float  # real: initial mutation step, as a fraction of each gene's range
    sigma_min: float  # real: smallest mutation step (fraction of range)
    local_share: float  # real: share of children made by mutating the best individual
    bits: tuple[int, ...]  # binary: bits per gene (sum 68 for the paper)

    def validate(self, where: str) -> None:
        w = f"{where}." if where else ""
        if self.population < 4:
            raise InputError(f"config key '{w}population': must be >= 4, got {self.population}")
        if not 0 <= self.elite < self.population:
            raise InputError(f"config key '{w}elite': must be in 0..population-1, got {self.elite}")
        if not 1 <= self.tournament <= self.population:
            raise InputError(f"config key '{w}tournament': must be in 1..population, got {self.tournament}")
        for name in ("crossover", "mutation", "local_share"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise InputError(f"config key '{w}{name}': must be in [0, 1], got {v}")
        if not 0.0 < self.sigma_min <= self.sigma <= 1.0:
            raise InputError(f"config key '{w}sigma': need 0 < sigma_min <= sigma <= 1, "
                             f"got sigma={self.sigma}, sigma_min={self.sigma_min}")
        if len(self.bits) != 7 or not all(2 <= b <= 30 for b in self.bits):
            raise InputError(f"config key '{w}bits': must list 7 bit counts in 2..30, got {list(self.bits)}")


def paper_params() -> GAParams:
    """The paper's configuration: 30 individuals, 68-bit binary chromosome."""
    return GAParams(coding="binary", population=30, elite=2, tournament=2, crossover=0.9,
                    mutation=1.0 / 68, sigma=0.2, sigma_min=0.001, local_share=0.0, bits=PAPER_BITS)


@dataclass(frozen=True)
class Region:
    """A box in gene space: lo[i] <= gene i <= hi[i]; periodic genes wrap instead of clipping."""

    lo: np.ndarray
    hi: np.ndarray
    periodic: np.ndarray  # (D,) bool

    @staticmethod
    def box(lo, hi, periodic=None) -> Region:
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        per = np.zeros(lo.shape, bool) if periodic is None else np.asarray(periodic, bool)
        if lo.shape != hi.shape or lo.ndim != 1 or per.shape != lo.shape or np.any(hi <= lo):
            raise ValueError("Region: lo < hi needed, same 1-D shape")
        return Region(lo, hi, per)

    @property
    def width(self) -> np.ndarray:
        return self.hi - self.lo

    def repair(self, g: np.ndarray) -> np.ndarray:
        """Wrap periodic genes into [lo, hi), clip the others into [lo, hi]."""
        g = np.array(g, dtype=np.float64, copy=True)
        w = self.width
        g = np.where(self.periodic, self.lo + np.mod(g - self.lo, w), np.clip(g, self.lo, self.hi))
        return g

    def contains(self, g: np.ndarray) -> np.ndarray:
        """(P,) bool: individual inside the box (periodic genes always are)."""
        inside = (g >= self.lo) & (g <= self.hi)
        return np.all(inside | self.periodic, axis=-1)

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """n genes drawn uniformly in the box."""
        return self.lo + rng.random((n, self.lo.size)) * self.width


class GA:
    """A persistent GA population (method steps 4-5).

    fitness: callable (P, D) genes -> (P,) fitness, higher is better.
    region: the search box; rng: the only source of randomness (same seed, same run).
    """

    def __init__(self, fitness: FitnessFn, region: Region, params: GAParams,
                 rng: np.random.Generator, seeds: np.ndarray | None = None) -> None:
        self.params = params
        self.rng = rng
        self.region = region
        self._fitness = fitness
        P, D = params.population, region.lo.size
        if params.coding == "binary" and len(params.bits) != D:
            raise ValueError(f"GA: {len(params.bits)} bit counts for {D} genes")
        self.genes = region.sample(rng, P)
        self.sigma = np.full(P, params.sigma)
        self.scores = np.full(P, -np.inf)
        self._stale = np.ones(P, bool)
        self.generation = 0
        self.evaluations = 0
        if seeds is not None and len(seeds):
            self.inject(seeds)

    # ------------------------------------------------------------------ population control

    def set_fitness(self, fitness: FitnessFn) -> None:
        """A new frame: the same population is scored against the new fitness from now on."""
        self._fitness = fitness
        self._stale[:] = True

    def set_region(self, region: Region, resample_outside: bool = True) -> None:
        """Replace the search box (tracking window or full volume). Individuals outside it are
        redrawn uniformly inside it (or clipped when `resample_outside` is False)."""
        self.region = region
        out = ~region.contains(self.genes)
        self.genes = region.repair(self.genes)
        if resample_outside and np.any(out):
            self.genes[out] = region.sample(self.rng, int(out.sum()))
            self.sigma[out] = self.params.sigma
        self._stale[:] = True

    def reset(self, region: Region | None = None) -> None:
        """Forget the population: a fresh uniform one over `region` (default: the current)."""
        if region is not None:
            self.region = region
        P = self.params.population
        self.genes = self.region.sample(self.rng, P)
        self.sigma[:] = self.params.sigma
        self._stale[:] = True

    def inject(self, genes: np.ndarray, sigma: float | None = None) -> None:
        """Put individuals (k, D) into the population in place of the worst (unscored first).
        At most population - 1 are taken so the current best survives."""
        genes = np.atleast_2d(np.asarray(genes, dtype=np.float64))
        k = min(len(genes), self.params.population - 1)
        if k <= 0:
            return
        order = np.argsort(np.where(self._stale, -np.inf, self.scores), kind="stable")
        slots = order[:k]
        self.genes[slots] = self.region.repair(genes[:k])
        self.sigma[slots] = self.params.sigma if sigma is None else sigma
        self._stale[slots] = True

    def set_genes(self, genes: np.ndarray) -> None:
        """Replace the whole population's genes (P, D), e.g. re-expressed in a moved camera's
        frame by the tracker; every individual is re-scored, mutation steps are kept."""
        genes = np.asarray(genes, dtype=np.float64)
        if genes.shape != self.genes.shape:
            raise ValueError(f"set_genes: expected shape {self.genes.shape}, got {genes.shape}")
        self.genes = self.region.repair(genes)
        self._stale[:] = True

    # ------------------------------------------------------------------ evolution

    def evaluate(self) -> None:
        """Score every individual whose score is stale (new, moved, or new frame)."""
        idx = np.flatnonzero(self._stale)
        if idx.size:
            f = np.asarray(self._fitness(self.genes[idx]), dtype=np.float64)
            self.scores[idx] = np.where(np.isfinite(f), f, -np.inf)
            self._stale[idx] = False
            self.evaluations += idx.size

    def best(self) -> tuple[np.ndarray, float]:
        """(genes (D,), fitness) of the best scored individual."""
        self.evaluate()
        i = int(np.argmax(self.scores))
        return self.genes[i].copy(), float(self.scores[i])

    def ranked(self) -> tuple[np.ndarray, np.ndarray]:
        """(genes (P, D), fitness (P,)) sorted best first."""
        self.evaluate()
        o = np.argsort(-self.scores, kind="stable")
        return self.genes[o].copy(), self.scores[o].copy()

    def step(self, generations: int = 1) -> tuple[np.ndarray, float]:
        """Advance `generations` generations; returns the best (genes, fitness)."""
        for _ in range(generations):
            self.evaluate()
            if self.params.coding == "binary":
                self._generation_binary()
            else:
                self._generation_real()
            self.generation += 1
        return self.best()

    def _select(self, n: int) -> np.ndarray:
        """Tournament selection: n parent indices."""
        k = self.params.tournament
        cand = self.rng.integers(0, self.params.population, size=(n, k))
        return cand[np.arange(n), np.argmax(self.scores[cand], axis=1)]

    def _next(self, children: np.ndarray, child_sigma: np.ndarray | None) -> None:
        E = self.params.elite
        order = np.argsort(-self.scores, kind="stable")
        elite = order[:E]
        genes = np.concatenate([self.genes[elite], children])
        scores = np.concatenate([self.scores[elite], np.full(len(children), -np.inf)])
        sig = self.sigma[elite] if child_sigma is None else np.concatenate([self.sigma[elite], child_sigma])
        self.genes = genes
        self.scores = scores
        if child_sigma is not None:
            self.sigma = sig
        self._stale = np.concatenate([np.zeros(E, bool), np.ones(len(children), bool)])

    def _generation_real(self) -> None:
        p, reg, rng = self.params, self.region, self.rng
        P, D = self.genes.shape
        n = P - p.elite
        w = reg.width
        a = self._select(n)
        b = self._select(n)
        ga, gb = self.genes[a], self.genes[b]
        # unwrap periodic genes of parent b next to parent a
        gb = np.where(reg.periodic, ga + (np.mod(gb - ga + w / 2, w) - w / 2), gb)
        # BLX-0.5 blend crossover, gene by gene
        lo, hi = np.minimum(ga, gb), np.maximum(ga, gb)
        d = hi - lo
        blend = lo - 0.5 * d + rng.random((n, D)) * 2.0 * d
        cross = rng.random(n) < p.crossover
        child = np.where(cross[:, None], blend, ga)
        sig = np.where(cross, np.sqrt(self.sigma[a] * self.sigma[b]), self.sigma[a])
        # local refinement: some children are mutants of the best individual
        n_local = round(p.local_share * n)
        if n_local:
            i_best = int(np.argmax(self.scores))
            child[:n_local] = self.genes[i_best]
            sig[:n_local] = self.sigma[i_best]
        # self-adaptive Gaussian mutation (log-normal step size, tau = 1/sqrt(D))
        sig = np.clip(sig * np.exp(rng.standard_normal(n) / np.sqrt(D)), p.sigma_min, 0.5)
        mutate = rng.random((n, D)) < p.mutation
        if n_local:
            mutate[:n_local] |= ~mutate[:n_local].any(axis=1)[:, None]  # a local child always moves
        child = child + mutate * rng.standard_normal((n, D)) * sig[:, None] * w
        self._next(reg.repair(child), sig)

    # --- binary chromosome (the paper's 68 bits)

    def encode(self, genes: np.ndarray) -> np.ndarray:
        """Genes (P, D) -> chromosomes (P, sum(bits)) bool, plain binary, MSB first."""
        reg = self.region
        out = []
        for i, b in enumerate(self.params.bits):
            levels = 2**b if reg.periodic[i] else 2**b - 1
            k = np.rint((genes[:, i] - reg.lo[i]) / reg.width[i] * levels).astype(np.int64)
            k = np.mod(k, 2**b) if reg.periodic[i] else np.clip(k, 0, 2**b - 1)
            out.append(((k[:, None] >> np.arange(b - 1, -1, -1)) & 1).astype(bool))
        return np.concatenate(out, axis=1)

    def decode(self, chrom: np.ndarray) -> np.ndarray:
        """Chromosomes (P, sum(bits)) -> genes (P, D)."""
        reg = self.region
        genes = np.empty((len(chrom), len(self.params.bits)))
        j = 0
        for i, b in enumerate(self.params.bits):
            k = chrom[:, j:j + b].astype(np.int64) @ (1 << np.arange(b - 1, -1, -1))
            levels = 2**b if reg.periodic[i] else 2**b - 1
            genes[:, i] = reg.lo[i] + k / levels * reg.width[i]
            j += b
        return genes

    def _generation_binary(self) -> None:
        p, rng = self.params, self.rng
        P = self.genes.shape[0]
        n = P - p.elite
        chrom = self.encode(self.genes)
        L = chrom.shape[1]
        a, b = self._select(n), self._select(n)
        ca, cb = chrom[a], chrom[b]
        # two-point crossover
        cuts = np.sort(rng.integers(0, L + 1, size=(n, 2)), axis=1)
        pos = np.arange(L)
        from_b = (pos >= cuts[:, :1]) & (pos < cuts[:, 1:]) & (rng.random(n) < p.crossover)[:, None]
        child = np.where(from_b, cb, ca)
        child ^= rng.random((n, L)) < p.mutation
        self._next(self.decode(child), None)
