"""Tracking that holds (issue 10): the real-time simulator runs a new user makes, scored against
the simulator's truth, beside the issue's targets.

Cases (each `python -m photoservo.cli track --sim --no-record --json ...` in a fresh process):
  default      --duration D: found share, hold error, frames per second, track error
  recorded     the same with the default recording (the README's first command; to a temp file)
  first run    the same with an empty NUMBA_CACHE_DIR (the warm start compiles before the clock)
  no motion    --no-motion --duration D: the creature drifts out of view of a still arm
  occlusion    --set sim.occlusion_s=[5.0, 7.0]: foam hides the creature for 2 s
  low_fps      --set sim.camera_fps=3: the vision loop at 3 fps (what a loaded machine leaves it)
  fps5         --set sim.camera_fps=5: the hold at 5 fps
  irregular    --set sim.heave_irregular=true: heave from five sinusoids (the tracker's heave model is one)

Targets (issue 10, "Done when"): first run found >= 90 % and hold <= 15 mm RMS (and this round's brief:
the hold <= 15 mm RMS in real time, default and recorded); no motion:
false_tracks 0 and track_error_mm.p95 <= 15 mm, ending out_of_view; occlusion: every
reacquisition_s <= 1.0 s and found >= 80 %; >= 30 fps steady on the default run; low_fps (this
round's brief): found >= 80 %, false_tracks 0.

The machine is shared (2 cores): the load average before and after each run and the runs' CPU
seconds are stored with the numbers; `--repeats N` runs each case N times and prints medians.

Prints a table and writes benchmarks/out/tracking.json.
Run: python benchmarks/tracking.py [--duration 20] [--repeats 1] [--cases default,no_motion,...] [--out JSON]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from photoservo.fileio import write_text_atomic

OUT = Path(__file__).resolve().parent / "out" / "tracking.json"

CASES = {
    "default": [],
    "recorded": ["--record", "{tmp}/run.rrd"],
    "first_run": [],  # and an empty NUMBA_CACHE_DIR
    "no_motion": ["--no-motion"],
    "occlusion": ["--set", "sim.occlusion_s=[5.0, 7.0]"],
    "low_fps": ["--set", "sim.camera_fps=3"],
    "fps5": ["--set", "sim.camera_fps=5"],
    "irregular": ["--set", "sim.heave_irregular=true"],
}


def run_case(name: str, duration: float) -> dict:
    """One `track --sim` run in a fresh process: its JSON summary, wall and CPU seconds, load."""
    env = dict(os.environ)
    tmp = tempfile.TemporaryDirectory() if name in ("first_run", "recorded") else None
    if name == "first_run":
        env["NUMBA_CACHE_DIR"] = tmp.name
    extra = [a.format(tmp=tmp.name if tmp else "") for a in CASES[name]]
    cmd = [sys.executable, "-m", "photoservo.cli", "track", "--sim", "--json", "--duration", str(duration), "-q",
           *([] if "--record" in extra else ["--no-record"]), *extra]
    load0 = os.getloadavg()
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    w0 = time.perf_counter()
    try:
        r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    finally:
        if tmp is not None:
            tmp.cleanup()
    wall = time.perf_counter() - w0
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if not r.stdout.strip():
        raise SystemExit(f"{name}: exit {r.returncode}, no summary: {r.stderr.strip()[-400:]}")
    s = json.loads(r.stdout.strip().splitlines()[-1])
    return {"case": name, "command": " ".join(cmd[1:]), "exit": r.returncode, "summary": s, "wall_s": wall,
            "cpu_s": (cpu1.ru_utime + cpu1.ru_stime) - (cpu0.ru_utime + cpu0.ru_stime),
            "load_before": load0, "load_after": os.getloadavg()}


def numbers(run: dict, duration: float) -> dict:
    """The issue's numbers of one run."""
    s = run["summary"]
    te = s.get("track_error_mm") or {}
    hold = s.get("hold_error_rms_mm", s.get("rms_position_error_mm"))
    return {"found_pct": 100.0 * s["found_ratio"], "hold_rms_mm": hold, "fps": s["frames"] / duration,
            "track_err_median_mm": te.get("median"), "track_err_p95_mm": te.get("p95"),
            "false_tracks": s.get("false_tracks"), "reacquisition_s": s.get("reacquisition_s"),
            "final_status": s.get("final_status"), "exit": run["exit"]}


def verdicts(case: str, n: dict) -> list[str]:
    """Each target of the case: 'name: value vs target ok|MISSED'."""
    def check(label: str, ok: bool, text: str) -> str:
        return f"{label} {text} {'ok' if ok else 'MISSED'}"
    f = n["found_pct"]
    out = []
    if case == "first_run":
        out += [check("found", f >= 90.0, f"{f:.0f} % (>= 90)"),
                check("hold", n["hold_rms_mm"] is not None and n["hold_rms_mm"] <= 15.0,
                      f"{n['hold_rms_mm']} mm RMS (<= 15)")]
    if case in ("default", "recorded"):
        out += [check("fps", n["fps"] >= 30.0, f"{n['fps']:.1f} (>= 30)"),
                check("hold", n["hold_rms_mm"] is not None and n["hold_rms_mm"] <= 15.0,
                      f"{n['hold_rms_mm']:.1f} mm RMS (<= 15)")]
    if case == "no_motion":
        p95 = n["track_err_p95_mm"]
        out += [check("false_tracks", n["false_tracks"] == 0, f"{n['false_tracks']} (0)"),
                check("track p95", p95 is not None and p95 <= 15.0, f"{p95} mm (<= 15)"),
                check("ends", n["final_status"] == "out_of_view", f"{n['final_status']} (out_of_view)")]
    if case == "occlusion":
        r = n["reacquisition_s"] or []
        out += [check("reacquisition", bool(r) and all(x is not None and x <= 1.0 for x in r), f"{r} s (<= 1.0)"),
                check("found", f >= 80.0, f"{f:.0f} % (>= 80)")]
    if case == "low_fps":
        out += [check("found", f >= 80.0, f"{f:.0f} % (>= 80)"),
                check("false_tracks", n["false_tracks"] == 0, f"{n['false_tracks']} (0)")]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--out", type=Path, default=OUT, help="the JSON to write (default benchmarks/out/tracking.json)")
    args = ap.parse_args()
    cases = args.cases.split(",")
    runs = [run_case(c, args.duration) for _ in range(args.repeats) for c in cases]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(args.out, json.dumps({"duration_s": args.duration, "repeats": args.repeats, "runs": runs},
                                           indent=1) + "\n")
    print(f"{'case':<10} {'found %':>7} {'hold mm':>8} {'fps':>5} {'trk med':>8} {'trk p95':>8} {'false':>5} "
          f"{'reacq s':>12} {'load':>9} {'CPU s':>6}  targets")
    table = {}
    for c in cases:
        rs = [r for r in runs if r["case"] == c]
        ns = [numbers(r, args.duration) for r in rs]
        med = {k: (float(np.median([n[k] for n in ns])) if all(isinstance(n[k], (int, float)) for n in ns) else ns[-1][k])
               for k in ns[0]}
        table[c] = {"median": med, "verdicts": verdicts(c, med)}

        def fmt(v, spec):
            return "-" if v is None else format(v, spec)
        load = f"{rs[-1]['load_before'][0]:.1f}>{rs[-1]['load_after'][0]:.1f}"
        reacq = "-" if not med["reacquisition_s"] else ",".join(fmt(x, ".2f") for x in med["reacquisition_s"])
        print(f"{c:<10} {med['found_pct']:>7.0f} {fmt(med['hold_rms_mm'], '8.1f')} {med['fps']:>5.1f} "
              f"{fmt(med['track_err_median_mm'], '8.1f')} {fmt(med['track_err_p95_mm'], '8.1f')} "
              f"{fmt(med['false_tracks'], '5.0f')} {reacq:>12} {load:>9} {float(np.median([r['cpu_s'] for r in rs])):>6.1f}"
              f"  {'; '.join(table[c]['verdicts'])}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(args.out, json.dumps({"duration_s": args.duration, "repeats": args.repeats, "table": table,
                                       "runs": runs}, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
