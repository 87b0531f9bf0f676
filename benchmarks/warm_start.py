"""Warm start (issue 10): how long the first run after installing spends compiling the numba
kernels, and how long a later run spends loading them — what `photoservo track` does before its
clock starts (servo/warm.py): the fitness kernels (vision process), the renderer's kernels (the
simulator's renderer process) and the arm's forward kinematics (robot/pa10_kernel.py; loaded
again by the control process).

Each measurement runs in a fresh Python process (numba keeps compiled code per process): with an
empty NUMBA_CACHE_DIR (a first run) and then again with the cache that run left (a later run).
Wall and CPU seconds of each kernel's warm-up are reported; the machine is shared (2 cores), so
the load average is stored and medians of repeated runs are printed.

Prints a table and writes benchmarks/out/warm_start.json.
Run: python benchmarks/warm_start.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from photoservo.fileio import write_text_atomic

OUT = Path(__file__).resolve().parent / "out" / "warm_start.json"
KERNELS = ("fitness", "renderer", "kinematics")

CHILD = r"""
import json, time
t0, c0 = time.perf_counter(), time.process_time()
from photoservo.config import load_config
from photoservo.robot import pa10_kernel
from photoservo.servo.warm import warm_kinematics
from photoservo.sim.run import build_sim
from photoservo.vision.warm import fitness_kernels, kernels_cached, warm_fitness
cfg = load_config(None, [])
out = {"imports_s": time.perf_counter() - t0}
w, c = time.perf_counter(), time.process_time()
cached = kernels_cached([pa10_kernel.fk_frames_kernel])
warm_kinematics()  # before build_sim, which computes the arm's kinematics
out["kinematics"] = {"wall_s": time.perf_counter() - w, "cpu_s": time.process_time() - c}
sim = build_sim(cfg)
out["cached_before"] = cached and kernels_cached(fitness_kernels(cfg.fitness) + sim.scene.kernels())
for name, warm in (("fitness", lambda: warm_fitness(sim.scene.model, sim.rig, cfg.fitness)),
                   ("renderer", sim.scene.warm)):
    w, c = time.perf_counter(), time.process_time()
    warm()
    out[name] = {"wall_s": time.perf_counter() - w, "cpu_s": time.process_time() - c}
print(json.dumps(out))
"""


def run_child(cache_dir: str) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
    r = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, check=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    load = os.getloadavg()
    runs: dict[str, list[dict]] = {"first": [], "later": []}
    for _ in range(args.repeats):
        with tempfile.TemporaryDirectory() as d:
            runs["first"].append(run_child(d))
            runs["later"].append(run_child(d))
    table = {}
    for kind, rs in runs.items():
        assert all(r["cached_before"] == (kind == "later") for r in rs), "cache state not as expected"
        table[kind] = {k: {m: float(np.median([r[k][m] for r in rs])) for m in ("wall_s", "cpu_s")}
                       for k in KERNELS}
    print(f"load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f}; medians of {args.repeats} fresh processes")
    print(f"{'kernel':<10} {'first run wall / CPU s':>24} {'later run wall / CPU s':>24}")
    for k in KERNELS:
        f, lt = table["first"][k], table["later"][k]
        print(f"{k:<10} {f['wall_s']:>11.2f} / {f['cpu_s']:<10.2f} {lt['wall_s']:>11.2f} / {lt['cpu_s']:<10.2f}")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(OUT, json.dumps({"load_average": load, "repeats": args.repeats, "median": table,
                                       "runs": runs}, indent=1) + "\n")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
