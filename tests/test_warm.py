"""Warm start of the compiled kernels (issue 10): servo/warm.py, vision/warm.py."""

import importlib
import os
import pkgutil
import subprocess
import sys

import numpy as np

import photoservo
from photoservo.config import load_config
from photoservo.robot import pa10
from photoservo.sim.run import build_sim
from photoservo.servo.warm import warm_start
from photoservo.vision.fitness import fitness, stereo_hue
from photoservo.vision.tracker import Tracker
from photoservo.vision.warm import dispatchers, fitness_kernels, kernels_cached


def _all_kernels() -> dict:
    """Every numba dispatcher defined anywhere in the photoservo package."""
    found = {}
    for info in pkgutil.walk_packages(photoservo.__path__, "photoservo."):
        if ".cli" in info.name:
            continue
        mod = importlib.import_module(info.name)
        found.update({f"{info.name}.{k}": v for k, v in dispatchers(mod).items()})
    return found


def test_after_the_warm_start_session_frames_compile_or_load_nothing():
    """Whatever kernel the session's frames run (render, hue, the tracker's acquisition and
    tracking) was compiled or loaded by warm_start: no dispatcher gains a signature after it."""
    cfg = load_config()
    sim = build_sim(cfg)
    kernels = _all_kernels()
    assert "photoservo.vision.fitness_kernel.counts_serial" in kernels
    assert "photoservo.sim.renderer_kernel.water_pass" in kernels
    warm_start(sim.scene.model, sim.rig, cfg.fitness, scene=sim.scene)
    assert kernels_cached(fitness_kernels(cfg.fitness) + sim.scene.kernels())  # and cached on disk now
    before = {k: len(d.signatures) for k, d in kernels.items()}
    tracker = Tracker.from_config(sim.scene.model, sim.rig, cfg, time_budget=False)
    T = pa10.fk(sim.q0) @ sim.rig.T_flange_left()
    for k in range(12):  # the acquisition (spread over frames), then tracking frames
        left, right = sim.scene.render(T, k / 30, T, k / 30)
        tracker.update(stereo_hue(left, right, cfg.fitness), left, right, T, k / 30)
    assert tracker.status == "tracking" and tracker.acquisitions == 1
    assert {k: len(d.signatures) for k, d in kernels.items()} == before


def test_an_empty_compile_cache_is_seen_before_compiling(tmp_path):
    """With an empty NUMBA_CACHE_DIR (a first run after installing) the kernels are not cached,
    so the session says it compiles; the check itself compiles and writes nothing."""
    code = ("from photoservo.config import load_config; from photoservo.sim.run import build_sim; "
            "from photoservo.vision.warm import fitness_kernels, kernels_cached; cfg = load_config(); "
            "s = build_sim(cfg); ks = fitness_kernels(cfg.fitness) + s.scene.kernels(); "
            "print(kernels_cached(ks), sum(len(k.signatures) for k in ks))")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "0"]
    # no index or code file of the checked kernels written (building the simulator computes the
    # arm's kinematics, whose kernel robot/pa10_kernel.py is compiled and cached then)
    written = [p.name for p in tmp_path.rglob("*.nb[ic]")]
    assert not [n for n in written if n.startswith(("fitness_kernel", "renderer_kernel"))], written


def test_warm_fitness_compiles_the_loops_own_signature():
    """One compiled signature per kernel: the warm-up's argument types are the loop's."""
    cfg = load_config()
    sim = build_sim(cfg)
    warm_start(sim.scene.model, sim.rig, cfg.fitness)
    assert all(k.signatures for k in fitness_kernels(cfg.fitness))  # every one compiled or loaded now
    T = pa10.fk(sim.q0) @ sim.rig.T_flange_left()
    left, right = sim.scene.render(T, 0.0, T, 0.0)
    R = np.eye(3)[None].repeat(5, 0)
    t = np.tile([0.0, 0.0, 600.0], (5, 1))
    frame = stereo_hue(left, right, cfg.fitness)
    fitness(R, t, np.full(5, 2.0), sim.scene.model, frame, sim.rig, cfg.fitness)
    # the detection's outline, as an acquisition computes it (its contour kernel compiled inside the
    # first acquisition made a first run's first track come 7 s into the session)
    from photoservo.vision.contour import stereo_chroma
    from photoservo.vision.detection import OutlineCues, outer_share
    from photoservo.vision.silhouette import distinctive_weight

    cues = OutlineCues(weight=distinctive_weight(frame.left, frame.right, sim.scene.model),
                       chroma=stereo_chroma(left, right))
    outer_share(R, t, np.full(5, 2.0), sim.scene.model, frame, sim.rig, cfg.fitness, cues)
    assert [len(k.signatures) for k in fitness_kernels(cfg.fitness)] == [1, 1, 1, 1]
