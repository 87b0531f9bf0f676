"""Fitness speed (issue 2 item 9, "speed"): ms per GA generation = one `fitness` call scoring the
whole population, with a photo-model of exactly 1000 sampling points (fixed, so a coarser
sampling cannot buy speed), at 30 individuals (the paper's population) and 100, beside the
paper's 0.213 s per generation.

Scene: a seeded synthetic squid scene (sim/scenes.random_scene) at 600 mm, its photo-model
resampled to exactly 1000 points (inner and outer in their natural proportion). Population:
the truth with Gaussian spread (40 mm, ~15 deg, x1.3 in alpha), like a GA mid-run.
Two rigs: the synthetic rig as written (lens distortion: the kernel's general path) and the
same rig without distortion (the kernel folds K into a homography: one division per point).

Kernels: the numpy reference, numba on one thread (the default) and numba-parallel (numba
threads over (individual, camera) jobs). Per configuration: median (and 10th/90th percentile)
wall ms per call over `--repeats` calls after one warm-up call, the CPU ms per call of the
process, the speed-up over the paper (213 ms / median) and numpy / numba in the same run.
JIT warm-up: a fresh process compiling into an empty cache (cold) and loading it (warm).
Wall time to converge: `estimate` with the default configuration from the default search volume
on `--converge-scenes` seeded scenes (median, p90, share within 1 s, generations, and the share
of the wall time spent in fitness calls).

The machine has 2 cores shared with other jobs: the load average is printed and stored; wall
times on a loaded machine are pessimistic, the CPU column is the steadier one.

Prints a table and writes benchmarks/out/fitness_speed.json.
Run: python benchmarks/fitness_speed.py [--repeats 300]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from photoservo.fileio import write_text_atomic
from photoservo.config import load_config
from photoservo.vision.fitness import (
    FitnessParams,
    fitness,
    fitness_reference,
    stereo_hue,
)
from photoservo.vision.photo_model import PhotoModel, build_photo_model
from photoservo.vision.rig import Camera, Rig
from photoservo.sim.scenes import random_scene

PAPER_S = 0.213  # the paper's seconds per generation (30 individuals, 68-bit GA)
N_POINTS = 1000


def model_with_points(model: PhotoModel, n: int, rng: np.random.Generator) -> PhotoModel:
    """The model with exactly n sampling points: a seeded subset keeping the inner/outer ratio."""
    n_in, n_out = len(model.inner_uv), len(model.outer_uv)
    if n_in + n_out < n:
        raise SystemExit(f"model has only {n_in + n_out} points, need {n}: lower photo_model.interval_px")
    k_in = round(n * n_in / (n_in + n_out))
    ii = np.sort(rng.choice(n_in, k_in, replace=False))
    oo = np.sort(rng.choice(n_out, n - k_in, replace=False))
    return dataclasses.replace(model, inner_uv=model.inner_uv[ii], inner_hue=model.inner_hue[ii],
                               outer_uv=model.outer_uv[oo])


def population(R0, t0, alpha0, P: int, rng: np.random.Generator):
    R = np.stack([cv2.Rodrigues(rng.normal(0, 0.15, 3))[0] @ R0 for _ in range(P)])
    t = t0 + rng.normal(0, 40, (P, 3))
    alpha = alpha0 * np.exp(rng.normal(0, 0.25, P))
    return R, t, alpha


def undistorted(rig: Rig) -> Rig:
    def cam(c: Camera) -> Camera:
        return Camera(c.size, c.K, np.zeros(5))
    return Rig(left=cam(rig.left), right=cam(rig.right), R=rig.R, T=rig.T)


def time_calls(fn, repeats: int) -> dict:
    fn()  # warm-up (compiles or loads the cache on the first configuration)
    walls = []
    c0 = time.process_time()
    for _ in range(repeats):
        w0 = time.perf_counter()
        fn()
        walls.append(time.perf_counter() - w0)
    cpu = (time.process_time() - c0) / repeats
    w = np.array(walls) * 1e3
    return {"median_ms": float(np.median(w)), "p10_ms": float(np.percentile(w, 10)),
            "p90_ms": float(np.percentile(w, 90)), "cpu_ms": cpu * 1e3, "repeats": repeats}


_WARMUP_SNIPPET = """
import time, numpy as np
t0 = time.perf_counter()
from photoservo.vision import fitness_kernel  # numba import + cache lookup
t1 = time.perf_counter()
from photoservo.config import load_config
from photoservo.vision.fitness import fitness, StereoHue
from photoservo.vision.photo_model import PhotoModel
from photoservo.sim.scenes import synthetic_rig
p = load_config().fitness
m = PhotoModel(inner_uv=np.zeros((3, 2)), inner_hue=np.zeros(3, np.uint8), outer_uv=np.ones((3, 2)),
               target_hues=np.zeros(180, bool), size_px=(1.0, 1.0), origin_px=(0.0, 0.0),
               mask=np.zeros((2, 2), np.uint8))
h = np.zeros((480, 640), np.uint8)
t2 = time.perf_counter()
fitness(np.eye(3), np.array([0, 0, 500.0]), 1.0, m, StereoHue(h, h), synthetic_rig(), p)
t3 = time.perf_counter()
print(t1 - t0, t3 - t2)
"""


def jit_warmup() -> dict:
    """Seconds for a fresh process to import the kernel module and make its first fitness call,
    with an empty numba cache (cold: compiles) and then with that cache (warm: loads)."""
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        for label in ("cold", "warm"):
            r = subprocess.run([sys.executable, "-c", _WARMUP_SNIPPET], env=env, capture_output=True,
                               text=True, check=True)
            imp, first = (float(x) for x in r.stdout.split())
            out[label] = {"import_s": imp, "first_call_s": first}
    return out


def converge_times(cfg, n_scenes: int) -> dict:
    """Wall time of `estimate` (default configuration, default search volume) on seeded scenes,
    squid / crab / fish in turn at 300-1500 mm: seconds, generations of the best island, total
    fitness evaluations, and the share of the time spent in fitness calls."""
    import photoservo.vision.detection as det_mod
    import photoservo.vision.pose_search as search_mod
    from photoservo.vision.estimator import estimate

    spent = []

    def timed_fitness(*a, **k):
        w0 = time.perf_counter()
        try:
            return fitness(*a, **k)
        finally:
            spent.append(time.perf_counter() - w0)

    rows = []
    # count the fitness share of the wall time: the GA islands (pose_search) and the detection null
    originals = {m: m.fitness for m in (search_mod, det_mod)}
    for m in originals:
        m.fitness = timed_fitness
    try:
        for i in range(n_scenes):
            sc = random_scene(3000 + i, cfg.synthetic, cfg.photo_model, kind=("squid", "crab", "fish")[i % 3])
            model = build_photo_model(sc.photo, cfg.photo_model)
            spent.clear()
            e = estimate(model, sc.left, sc.right, sc.rig, cfg.ga, cfg.estimator, cfg.fitness, seed=i)
            rows.append({"seconds": e.seconds, "generations": e.generations, "evaluations": e.evaluations,
                         "found": e.found, "converged": e.generations < cfg.estimator.max_generations,
                         "fitness_seconds": float(sum(spent)),
                         "points": len(model.inner_uv) + len(model.outer_uv)})
    finally:
        for m, f in originals.items():
            m.fitness = f
    sec = np.array([r["seconds"] for r in rows])
    return {"scenes": rows, "median_s": float(np.median(sec)), "p90_s": float(np.percentile(sec, 90)),
            "within_1s": float(np.mean(sec <= 1.0)),
            "median_generations": float(np.median([r["generations"] for r in rows])),
            "fitness_share": float(sum(r["fitness_seconds"] for r in rows) / sec.sum())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=300, help="timed calls per configuration (numba)")
    ap.add_argument("--numpy-repeats", type=int, default=30, help="timed calls per configuration (numpy)")
    ap.add_argument("--no-warmup", action="store_true", help="skip the JIT warm-up subprocesses")
    ap.add_argument("--converge-scenes", type=int, default=12, help="scenes for the wall time to converge (0: skip)")
    args = ap.parse_args()

    cfg = load_config()
    rng = np.random.default_rng(0)
    sc = random_scene(7, cfg.synthetic, cfg.photo_model, kind="squid", distance_mm=600.0, tilt_deg=20.0)
    photo_params = dataclasses.replace(cfg.photo_model, interval_px=2.0, max_points=20000)
    model = model_with_points(build_photo_model(sc.photo, photo_params), N_POINTS, rng)
    truth = sc.truth
    R0, t0, a0 = np.array(truth["rotation"]), np.array(truth["position_mm"]), truth["alpha_px_per_mm"]
    frame = stereo_hue(sc.left, sc.right, cfg.fitness)
    load_before = os.getloadavg()

    rows = []
    for rig_name, rig in (("distorted", sc.rig), ("ideal", undistorted(sc.rig))):
        for P in (30, 100):
            R, t, alpha = population(R0, t0, a0, P, np.random.default_rng(P))
            res = {}
            for kernel in ("numpy", "numba", "numba-parallel"):
                p: FitnessParams = dataclasses.replace(cfg.fitness, kernel=kernel)
                n = args.numpy_repeats if kernel == "numpy" else args.repeats
                res[kernel] = time_calls(lambda p=p, R=R, t=t, alpha=alpha, rig=rig: fitness(R, t, alpha, model, frame, rig, p), n)
            same = np.allclose(fitness(R, t, alpha, model, frame, rig, cfg.fitness),
                               fitness_reference(R, t, alpha, model, frame, rig, cfg.fitness), atol=1e-12)
            for kernel, r in res.items():
                rows.append({"rig": rig_name, "individuals": P, "points": N_POINTS, "kernel": kernel, **r,
                             "x_paper": PAPER_S * 1e3 / r["median_ms"],
                             "numpy_over_this": res["numpy"]["median_ms"] / r["median_ms"],
                             "equals_reference": bool(same)})
    conv = converge_times(cfg, args.converge_scenes) if args.converge_scenes > 0 else None
    load_after = os.getloadavg()
    warm = None if args.no_warmup else jit_warmup()

    print(f"fitness speed: {N_POINTS} sampling points, paper {PAPER_S * 1e3:.0f} ms/generation; "
          f"load average {load_before[0]:.2f} -> {load_after[0]:.2f} on {os.cpu_count()} CPUs "
          "(shared machine: wall times are pessimistic)")
    hdr = (f"{'rig':<10}{'P':>4} {'kernel':<15}{'median ms':>10}{'p10':>8}{'p90':>8}{'cpu ms':>8}"
           f"{'x paper':>9}{'numpy/this':>11}")
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        print(f"{r['rig']:<10}{r['individuals']:>4} {r['kernel']:<15}{r['median_ms']:>10.3f}{r['p10_ms']:>8.3f}"
              f"{r['p90_ms']:>8.3f}{r['cpu_ms']:>8.3f}{r['x_paper']:>9.0f}{r['numpy_over_this']:>11.1f}")
    target = next(r for r in rows if r["rig"] == "distorted" and r["individuals"] == 30 and r["kernel"] == "numba")
    print(f"target <= 0.5 ms/generation at 30 x 1000 (distorted rig, default kernel): "
          f"{target['median_ms']:.3f} ms median -> {'MET' if target['median_ms'] <= 0.5 else 'NOT MET'}")
    if conv:
        print(f"wall time to converge (estimate, default config and search volume, {len(conv['scenes'])} scenes): "
              f"median {conv['median_s']:.2f} s, p90 {conv['p90_s']:.2f} s, {conv['within_1s']:.0%} within 1 s, "
              f"median {conv['median_generations']:.0f} generations; fitness calls are "
              f"{conv['fitness_share']:.0%} of the wall time")
    if warm:
        print(f"JIT warm-up (fresh process): cold cache import {warm['cold']['import_s']:.2f} s + first call "
              f"{warm['cold']['first_call_s']:.2f} s (compiles); warm cache import {warm['warm']['import_s']:.2f} s"
              f" + first call {warm['warm']['first_call_s']:.3f} s")
    out = Path(__file__).parent / "out" / "fitness_speed.json"
    write_text_atomic(out, json.dumps({
        "paper_ms_per_generation": PAPER_S * 1e3, "points": N_POINTS, "cpus": os.cpu_count(),
        "load_average_before": load_before, "load_average_after": load_after,
        "target_ms": 0.5, "target_met": target["median_ms"] <= 0.5,
        "rows": rows, "converge": conv, "jit_warmup": warm}, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
