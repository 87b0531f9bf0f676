"""PA-10 kinematics and Ruckig motion: time per call and IK success rate.

    python benchmarks/kinematics_motion.py [--repeats 5] [--poses 200]

Prints a table and writes benchmarks/out/kinematics_motion.json. Times are the median over
`--repeats` runs (per-step p99 over all steps as well). IK poses are fk of joint vectors drawn
uniformly inside the joint ranges (seeded), solved from HOME_Q and from the true q plus
N(0, 0.2 rad) noise (the servo's case: start near the answer). Motion steps run on a perfect
arm (measured state = last setpoint) at the default [motion] config. The control period at
250 Hz is 4 ms: a step must stay well under it next to the vision work.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import time
from pathlib import Path

import numpy as np

from photoservo.fileio import write_text_atomic
from photoservo.robot.pa10 import (
    HOME_Q,
    IKError,
    dls_step,
    fk,
    ik,
    jacobian,
    load_limits,
)
from photoservo.geometry import pose_error
from photoservo.servo.motion import Motion, MotionParams
from photoservo.tomlconf import build_dataclass, configs_dir, read_toml

LIM = load_limits()
PARAMS = build_dataclass(MotionParams, read_toml(configs_dir() / "default.toml")["motion"], "motion")


def per_call_us(fn, n: int, repeats: int) -> float:
    runs = []
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(n):
            fn()
        runs.append((time.perf_counter() - t) / n * 1e6)
    return statistics.median(runs)


def ik_rows(n_poses: int, repeats: int) -> list[dict]:
    rows = []
    for start in ("HOME_Q", "true q + N(0, 0.2 rad)"):
        rates, times, errs = [], [], []
        for r in range(repeats):
            rng = np.random.default_rng(r)
            ok = 0
            t_all = []
            for q_true in rng.uniform(LIM.q_min, LIM.q_max, size=(n_poses, 7)):
                T = fk(q_true)
                q0 = HOME_Q if start == "HOME_Q" else q_true + rng.normal(0, 0.2, 7)
                t = time.perf_counter()
                try:
                    q = ik(T, q0, LIM)
                    ok += 1
                    e = pose_error(T, fk(q))
                    errs.append(float(np.linalg.norm(e[:3])))
                except IKError:
                    pass
                t_all.append(time.perf_counter() - t)
            rates.append(ok / n_poses)
            times.append(statistics.median(t_all) * 1e3)
        rows.append({"case": f"ik from {start}", "success_rate": statistics.median(rates),
                     "median_ms": statistics.median(times), "max_residual_mm": max(errs)})
    return rows


def motion_row(name: str, make, step, n: int, repeats: int, prep=None) -> dict:
    """Time `step(m, q, dq, x)` only; x = prep(q) (e.g. the servo's DLS solve) is not timed."""
    meds, all_ms = [], []
    for _ in range(repeats):
        m = make()
        q, dq = HOME_Q.copy(), np.zeros(7)
        ts = []
        for _ in range(n):
            x = prep(q) if prep is not None else None
            t = time.perf_counter()
            sp = step(m, q, dq, x)
            ts.append((time.perf_counter() - t) * 1e3)
            q, dq = sp.q, sp.dq
        meds.append(statistics.median(ts))
        all_ms += ts
    return {"case": name, "steps": n, "median_ms": statistics.median(meds),
            "p99_ms": float(np.percentile(all_ms, 99)), "max_ms": max(all_ms)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--poses", type=int, default=200)
    args = ap.parse_args()
    calls = [
        {"case": "fk", "us": per_call_us(lambda: fk(HOME_Q), 2000, args.repeats)},
        {"case": "jacobian", "us": per_call_us(lambda: jacobian(HOME_Q), 2000, args.repeats)},
        {"case": "dls_step (k_null=1)", "us": per_call_us(
            lambda: dls_step(HOME_Q, np.ones(6), 0.05, k_null=1.0), 2000, args.repeats)},
    ]
    target = HOME_Q + np.radians([30, 10, -20, 20, 60, -30, 90])
    servo = np.radians([3, -2, 2, 2, -4, 3, 5])
    down = np.array([0.0, 0.0, -200.0, 0.0, 0.0, 0.0])
    near_water = dataclasses.replace(PARAMS, z_min_mm=450.0)
    motion = [
        motion_row("move_step (HOME -> far target)", lambda: Motion(PARAMS, LIM),
                   lambda m, q, dq, _: m.move_step(q, dq, target), 500, args.repeats),
        motion_row("velocity_step (servo-like target)", lambda: Motion(PARAMS, LIM),
                   lambda m, q, dq, _: m.velocity_step(q, dq, servo), 500, args.repeats),
        motion_row("velocity_step (descending to z_min 450 mm)", lambda: Motion(near_water, LIM),
                   lambda m, q, dq, dq_t: m.velocity_step(q, dq, dq_t), 500, args.repeats,
                   prep=lambda q: dls_step(q, down, 0.05, k_null=1.0)),
        motion_row("stop_step (at rest)", lambda: Motion(PARAMS, LIM),
                   lambda m, q, dq, _: m.stop_step(q, dq), 500, args.repeats),
    ]
    iks = ik_rows(args.poses, args.repeats)
    load = os.getloadavg()[0]
    print(f"# machine load average {load:.1f} on {os.cpu_count()} CPUs (shared; times are inflated when loaded)")
    print(f"{'call':44s} {'us':>9s}")
    for r in calls:
        print(f"{r['case']:44s} {r['us']:9.1f}")
    print(f"\n{'motion step':44s} {'median ms':>10s} {'p99 ms':>8s} {'max ms':>8s}")
    for r in motion:
        print(f"{r['case']:44s} {r['median_ms']:10.3f} {r['p99_ms']:8.3f} {r['max_ms']:8.3f}")
    print(f"\n{'inverse kinematics':44s} {'success':>8s} {'median ms':>10s} {'max res. mm':>12s}")
    for r in iks:
        print(f"{r['case']:44s} {r['success_rate']:8.1%} {r['median_ms']:10.2f} {r['max_residual_mm']:12.4f}")
    out = Path(__file__).resolve().parent / "out" / "kinematics_motion.json"
    out.parent.mkdir(exist_ok=True)
    write_text_atomic(out, json.dumps({"load_average": load, "calls_us": calls, "motion_steps": motion, "ik": iks,
                               "repeats": args.repeats, "poses": args.poses}, indent=2))
    print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
