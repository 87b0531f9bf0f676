"""Real-time tracking speed (issue 5 item 8): per-stage timings of the session loop and frames
per second end to end, (a) on PRE-RENDERED simulator frames — the product's own cost: hue image,
tracker (a few GA generations), recording — and (b) with the LIVE simulator in real time: the
controller emulator on a pty behind the real serial link, the control thread at 250 Hz and the
renderer in the loop; plus the control period's lateness (p50, p99, max) during (b).

Targets: >= 30 frames per second end to end on this 2-core machine (stretch 60), control period
p99 within 2 ms. The machine is shared: the load average is printed and stored; medians of
repeated runs.

Prints a table and writes benchmarks/out/track_speed.json.
Run: python benchmarks/track_speed.py [--frames 90] [--live-s 15] [--repeats 3]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from photoservo.fileio import write_text_atomic
from photoservo.robot import pa10
from photoservo.sim.emulator import Emulator
from photoservo.config import load_config
from photoservo.record.recorder import Recorder
from photoservo.servo.scores import Scores
from photoservo.servo.session import Frame, vision_step
from photoservo.sim.run import build_sim, run_sim_realtime
from photoservo.vision.tracker import Tracker

OUT = Path(__file__).resolve().parent / "out" / "track_speed.json"


def prerendered(cfg, n_frames: int, record: bool) -> dict:
    """Per-stage ms on frames rendered beforehand along the target's drift (cameras following)."""
    sim = build_sim(cfg)
    T_fl = sim.rig.T_flange_left()
    T0 = pa10.fk(sim.q0) @ T_fl
    frames = []
    for k in range(n_frames):
        t = k / cfg.sim.camera_fps
        T = T0.copy()
        T[:3, 3] += sim.scene.motion.v * t  # cameras following the drift
        left, right = sim.scene.render(T, t, T, t + cfg.sim.lr_skew_s)
        frames.append(Frame(k, t, t + cfg.sim.lr_skew_s, t, left, right, T))
    tracker = Tracker.from_config(sim.scene.model, sim.rig, cfg, seed=0)
    sc = Scores()
    with tempfile.TemporaryDirectory() as d:
        rec = Recorder.from_config(cfg.recording, "bench", Path(d) / "b.rrd") if record else None
        try:
            walls = []
            for fr in frames:
                c0 = time.perf_counter()
                vision_step(fr, tracker, cfg, sc, rec, sim.truth)
                walls.append(1e3 * (time.perf_counter() - c0))
        finally:
            if rec is not None:
                rec.close()
    steady = walls[5:]  # the first frames include the acquisition from the full volume
    acq = walls[:5]
    out = {k: float(np.median(v[5:])) for k, v in sc.timings_ms.items()}
    out.update(frame_ms=float(np.median(steady)), frame_p90_ms=float(np.percentile(steady, 90)),
               fps=1e3 / float(np.median(steady)), acquisition_ms=float(max(acq)),
               found_ratio=sc.found / max(1, sc.frames))
    return out


def live(cfg, seconds: float, rt_priority: int | None = None) -> dict:
    sim = build_sim(cfg)
    emu = Emulator(cfg.emulator, sim.limits, q0=sim.q0)
    emu.start()
    try:
        cfg = dataclasses.replace(cfg, servo=dataclasses.replace(cfg.servo, settle_s=min(5.0, seconds / 2)))
        sc = run_sim_realtime(cfg, seconds, sim, emu, rt_priority=rt_priority)
    finally:
        emu.stop()
    late = np.asarray(sc.timings_ms.get("control_late", [np.nan]))
    s = sc.summary()
    return {
        **{k: float(np.median(v)) for k, v in sc.timings_ms.items() if k != "control_late"},
        "fps": sc.frames / seconds, "frames": sc.frames, "found_ratio": s["found_ratio"],
        "control_late_p50_ms": float(np.percentile(late, 50)), "control_late_p99_ms": float(np.percentile(late, 99)),
        "control_late_max_ms": float(late.max()), "hold_error_rms_mm": s["hold_error_rms_mm"],
        "watchdog": bool(emu.model.watchdog_fired), "faults": s["faults"],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=90)
    ap.add_argument("--live-s", type=float, default=15.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--rt-priority", type=int, default=None, metavar="N",
                    help="live runs: control process at SCHED_FIFO priority N (as track --rt-priority)")
    a = ap.parse_args()
    cfg = load_config()
    load = os.getloadavg()
    runs_pre = [prerendered(cfg, a.frames, record=False) for _ in range(a.repeats)]
    runs_rec = [prerendered(cfg, a.frames, record=True) for _ in range(a.repeats)]
    runs_live = [live(cfg, a.live_s, a.rt_priority) for _ in range(a.repeats)]

    def med(runs, key):
        vals = [r[key] for r in runs if key in r]
        return float(np.median(vals)) if vals else float("nan")

    print(f"load average {load[0]:.1f} on {os.cpu_count()} cores; medians of {a.repeats} runs; "
          f"live control process priority: {a.rt_priority or 'normal'}")
    print(f"{'stage (median ms per frame)':<34}{'pre-rendered':>14}{'+ recording':>14}{'live sim':>12}")
    for key in ("render", "capture", "hue", "ga", "record", "frame_ms", "frame", "control_ms"):
        print(f"{key:<34}{med(runs_pre, key):>14.2f}{med(runs_rec, key):>14.2f}{med(runs_live, key):>12.2f}")
    print(f"{'frames per second':<34}{med(runs_pre, 'fps'):>14.1f}{med(runs_rec, 'fps'):>14.1f}{med(runs_live, 'fps'):>12.1f}")
    print(f"{'found ratio':<34}{med(runs_pre, 'found_ratio'):>14.2f}{med(runs_rec, 'found_ratio'):>14.2f}"
          f"{med(runs_live, 'found_ratio'):>12.2f}")
    print(f"acquisition from the full volume: {med(runs_pre, 'acquisition_ms'):.0f} ms (first frames)")
    print(f"live control period lateness: p50 {med(runs_live, 'control_late_p50_ms'):.2f} ms, "
          f"p99 {med(runs_live, 'control_late_p99_ms'):.2f} ms, max {med(runs_live, 'control_late_max_ms'):.2f} ms; "
          f"watchdog fired in {sum(r['watchdog'] for r in runs_live)} of {len(runs_live)} runs")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(OUT, json.dumps({"load_average": load, "rt_priority": a.rt_priority, "prerendered": runs_pre, "prerendered_recording": runs_rec,
                                       "live": runs_live}, indent=1, default=float))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
