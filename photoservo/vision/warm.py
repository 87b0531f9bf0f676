"""Warm start of the compiled (numba) kernels (issue 10): a session compiles or loads every kernel
it will run BEFORE its clock starts, so the first frame after `pip install` is as fast as any.

numba compiles a kernel on its first call and caches the machine code on disk (`cache=True`,
next to the sources or in NUMBA_CACHE_DIR); a later process only loads it. Both happen at the
first call, which inside a session means: the first frame stalls for seconds (compiling) or about
half a second (loading), the creature drifts on and the track is lost. `warm_fitness` makes that
first call on an empty frame of the session's own rig and photo-model, so every argument has the
type it has in the loop (one compiled signature, the one the loop needs). `kernels_cached` tells
beforehand whether it will compile, so the session can say why it waits.
"""

from __future__ import annotations

import time
from types import ModuleType

import numpy as np

from photoservo.vision.fitness import FitnessParams, StereoHue, fitness
from photoservo.vision.photo_model import NO_HUE, PhotoModel
from photoservo.vision.rig import Rig


def dispatchers(module: ModuleType) -> dict:
    """The numba kernels (`njit` dispatchers) defined in `module`, by name."""
    from numba.core.dispatcher import Dispatcher

    return {k: v for k, v in vars(module).items()
            if isinstance(v, Dispatcher) and getattr(v.py_func, "__module__", None) == module.__name__}


def kernels_cached(kernels: list) -> bool:
    """True when every dispatcher in `kernels` has compiled code in numba's on-disk cache for its
    current source (its index file exists, is of this numba version and the source is unchanged),
    i.e. its first call loads instead of compiling. Reads numba's cache index through the
    dispatcher's cache object (`_cache._cache_file`, numba 0.5x-0.6x); if that layout changes,
    answers False (the caller then announces a compile that may turn out to be a load)."""
    try:
        return all(bool(k._cache._cache_file._load_index()) for k in kernels)
    except Exception:  # noqa: BLE001 - a numba internal changed: assume nothing is cached
        return False


def fitness_kernels(params: FitnessParams) -> list:
    """The dispatchers a GA's fitness evaluation and an acquisition's detection call from Python
    with these params: the counting kernel (serial or parallel) and `combine`, the contour kernel
    (the contour rule's counts and the detection's outline, `vision/contour.py`) - none of them
    for the numpy reference - and the genes' decoding into poses (`genes_kernel.decode_genes`,
    always compiled)."""
    from photoservo.vision.genes_kernel import decode_genes

    if params.kernel == "numpy":
        return [decode_genes]
    from photoservo.vision import contour
    from photoservo.vision import fitness_kernel as fk

    return [fk.counts_parallel if params.kernel == "numba-parallel" else fk.counts_serial, fk.combine,
            contour._contour_kernel, decode_genes]


def warm_fitness(model: PhotoModel, rig: Rig, params: FitnessParams) -> float:
    """Compile or load the fitness kernels (method step 3) and the detection's contour kernel with
    the loop's own argument types: one call of each on an empty (no-hue, no-chroma) frame of the
    rig's image size, the model 500 mm ahead of the left camera at alpha 1 px/mm. Returns the
    seconds it took."""
    t0 = time.perf_counter()
    frame = StereoHue(left=np.full((rig.left.height, rig.left.width), NO_HUE, np.uint8),
                      right=np.full((rig.right.height, rig.right.width), NO_HUE, np.uint8))
    R, t, alpha = np.eye(3)[None], np.array([[0.0, 0.0, 500.0]]), np.array([1.0])
    fitness(R, t, alpha, model, frame, rig, params)
    if params.kernel != "numpy":  # the detection's outline (and the contour rule): vision/contour.py
        from photoservo.vision.contour import StereoChroma, outline_spill

        ab = StereoChroma(left=np.zeros(frame.left.shape + (2,), np.uint8),
                          right=np.zeros(frame.right.shape + (2,), np.uint8))
        outline_spill(R, t, alpha, model, frame, ab, rig, params, np.zeros(256))
    _warm_decode(rig)
    return time.perf_counter() - t0


def _warm_decode(rig: Rig) -> None:
    """One `decode_genes` call with `GeneSpace.decode`'s argument types (one individual)."""
    from photoservo.vision.genes_kernel import decode_genes

    g = np.array([[rig.left.K[0, 2], rig.left.K[1, 2], 2.0, 0.0, 0.0, 0.0, 0.0]])
    decode_genes(g, True, 1.0, np.ascontiguousarray(rig.left.K, np.float64), float(rig.left.K[0, 0]),
                 np.array([200.0, 3000.0, 0.05, 20.0, 1e6]), np.ascontiguousarray(rig.R, np.float64),
                 np.ascontiguousarray(rig.T, np.float64).reshape(3), np.zeros((2, 6)),
                 np.empty((1, 3, 3)), np.empty((1, 3)), np.empty(1), np.empty(1, np.bool_))
