"""Warm start of a tracking session (issue 10): every compiled kernel the session runs is
compiled (first run after installing) or loaded from numba's cache BEFORE the session's clock
starts — before the arm is enabled and before the simulated world moves — so the first frame is
tracked like any other. On a first run it says so in one line (the compile takes a while).

The kernels: the stereo fitness (vision/fitness_kernel.py, in the vision process), the arm's
forward kinematics (robot/pa10_kernel.py; the control process loads it again before its loop:
`warm_kinematics`) and, in the simulator, the renderer's water pass (sim/renderer_kernel.py, in
the renderer process, which warms itself the same way before it reports ready: `SimScene.warm`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

from photoservo.robot import pa10
from photoservo.vision.fitness import FitnessParams
from photoservo.vision.photo_model import PhotoModel
from photoservo.vision.rig import Rig
from photoservo.vision.warm import fitness_kernels, kernels_cached, warm_fitness

COMPILE_NOTICE = ("first run after installing: compiling the numba kernels (about {s:.0f} s of CPU, once; "
                  "later runs load them)")
FIRST_COMPILE_CPU_S = 19  # measured: benchmarks/warm_start.py (fitness 11.9 s, renderer 5.2 s, kinematics 1.5 s of CPU)


def warm_kinematics() -> float:
    """Compile or load the forward-kinematics kernel (robot/pa10_kernel.py) with the control
    loop's argument types. Returns the seconds it took."""
    t0 = time.perf_counter()
    pa10.fk_frames(pa10.HOME_Q)
    return time.perf_counter() - t0


@dataclass(frozen=True)
class WarmStart:
    """What the warm start did: whether it had to compile, and how long it took (s)."""

    compiled: bool
    seconds: float


def warm_start(model: PhotoModel, rig: Rig, fit_params: FitnessParams, *, scene=None, render_here: bool = True,
               say: Callable[[str], None] | None = None) -> WarmStart:
    """Compile or load the session's kernels now (module docstring): the fitness kernels for
    `model` seen through `rig` and, when `scene` (a sim.world.SimScene) is given, the renderer's
    — here when `render_here`, else the renderer process warms them itself and they only count
    for the notice. `say` gets the one-line notice on a first run."""
    t0 = time.perf_counter()
    from photoservo.robot import pa10_kernel

    kernels = fitness_kernels(fit_params) + [pa10_kernel.fk_frames_kernel]
    if scene is not None:
        kernels += scene.kernels()
    compiled = not kernels_cached(kernels)
    if compiled and say is not None:
        say(COMPILE_NOTICE.format(s=FIRST_COMPILE_CPU_S))
    warm_fitness(model, rig, fit_params)
    warm_kinematics()
    if scene is not None and render_here:
        scene.warm()
    return WarmStart(compiled, time.perf_counter() - t0)
