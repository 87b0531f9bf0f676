"""The main job end to end, two checkouts against each other (issue 10's fps target): `photoservo
track --sim --duration D --json` with the default recording, each run a fresh process whose
PYTHONPATH is one checkout, the two alternately (A B A B ...) so both see the same machine.

Per run: frames per second over the session (frames / D), found share, track error against the
simulator's truth (median, p95), hold error, the loop's stage medians (capture, hue, ga, record,
frame) and the CPU seconds of the whole run (every process of the session, children reaped:
warm start and shutdown included), with the load average before and after. Printed: each run,
then per checkout the medians and the ratios B / A. The recordings go to a temporary folder.

Compile each checkout's kernels once before timing (a first run compiles them: `--warm`).

Prints a table and writes benchmarks/out/track_ab.json.
Run: python benchmarks/track_ab.py --a OLD_CHECKOUT [--b .] [--repeats 3] [--duration 20] [--warm]
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

OUT = Path(__file__).resolve().parent / "out" / "track_ab.json"


def run(tree: Path, duration: float, cwd: str) -> dict:
    """One `track --sim` session of the checkout at `tree`, its summary and CPU seconds."""
    load = os.getloadavg()[0]
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    p = subprocess.run([sys.executable, "-m", "photoservo.cli", "track", "--sim", "--duration", str(duration), "--json"],
                       cwd=cwd, env=dict(os.environ, PYTHONPATH=str(tree)), capture_output=True, text=True)
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    try:
        d = json.loads(p.stdout)
    except json.JSONDecodeError:
        return {"exit": p.returncode, "error": p.stderr.strip().splitlines()[-1:] or ["no output"]}
    return {"exit": p.returncode, "load": load, "load_end": os.getloadavg()[0], "fps": d["frames"] / duration,
            "frames": d["frames"], "found": d["found_ratio"], "track_error_mm": d["track_error_mm"],
            "hold_error_rms_mm": d["hold_error_rms_mm"], "timings_ms": d["timings_ms_median"],
            "cpu_s": (r1.ru_utime + r1.ru_stime) - (r0.ru_utime + r0.ru_stime)}


def medians(runs: list[dict]) -> dict:
    ok = [r for r in runs if "fps" in r]

    def med(f) -> float:
        vals = [f(r) for r in ok]
        vals = [np.nan if v is None else v for v in vals]
        return float(np.median(vals)) if vals else float("nan")
    out = {"runs": len(ok), "fps": med(lambda r: r["fps"]), "found": med(lambda r: r["found"]),
           "track_error_median_mm": med(lambda r: r["track_error_mm"]["median"]),
           "track_error_p95_mm": med(lambda r: r["track_error_mm"]["p95"]),
           "hold_error_rms_mm": med(lambda r: r["hold_error_rms_mm"]), "cpu_s": med(lambda r: r["cpu_s"])}
    for k in ("capture", "hue", "ga", "record", "frame"):
        out[f"{k}_ms"] = med(lambda r: r["timings_ms"].get(k))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a", required=True, type=Path, help="the checkout to compare against (e.g. main before a change)")
    ap.add_argument("--b", default=Path(__file__).resolve().parent.parent, type=Path, help="the checkout measured (this one)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--warm", action="store_true", help="one untimed short run of each first (compiles the kernels)")
    a = ap.parse_args()
    trees = {"a": a.a.resolve(), "b": a.b.resolve()}
    runs: dict[str, list[dict]] = {"a": [], "b": []}
    with tempfile.TemporaryDirectory() as cwd:  # the recordings land in cwd/logs
        if a.warm:
            for tree in trees.values():
                run(tree, 1.0, cwd)
        for i in range(a.repeats):
            for name, tree in trees.items():
                r = run(tree, a.duration, cwd)
                runs[name].append(r)
                print(f"{name} {i}: " + json.dumps(r), flush=True)
    m = {name: medians(rs) for name, rs in runs.items()}
    print(f"medians of {a.repeats} runs of {a.duration:.0f} s each, alternately; a = {trees['a']}, b = {trees['b']}")
    print(f"{'':<28}{'a':>12}{'b':>12}{'b / a':>10}")
    for k in m["a"]:
        va, vb = m["a"][k], m["b"][k]
        print(f"{k:<28}{va:>12.2f}{vb:>12.2f}{(vb / va if va else float('nan')):>10.2f}")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(OUT, json.dumps({"a": str(trees["a"]), "b": str(trees["b"]), "duration_s": a.duration,
                                       "medians": m, "runs": runs}, indent=1, default=float))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
