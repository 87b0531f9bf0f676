"""The main job end to end, checkouts against each other (issue 10's fps target): `photoservo
track --sim --duration D --json` with the default recording, each run a fresh process whose
PYTHONPATH is one checkout, the checkouts alternately (A B C A B C ...) so all see the same
machine.

Per run: frames per second over the session (frames / D), found share, track error against the
simulator's truth (median, p95), hold error, the loop's stage medians (capture, hue, ga, record,
frame), the CPU seconds of the whole run (every process of the session, children reaped: warm
start and shutdown included) and of each of its processes (polled, in start order: today the
session, the emulator, the recorder, the renderer, the control process, the video encoder), with
the load average before and after.
Printed: each run, then per checkout the medians and the ratios to the first. The recordings go
to a temporary folder.

A checkout is PATH, or PATH:MODULE for an older tree whose CLI module was another
(`/tmp/old:photoservo.servo.cli`); `--extra 'NAME=ARGS'` adds a variant of the LAST checkout
with more track arguments (e.g. `norec=--no-record`). Compile each checkout's kernels once
before timing (a first run compiles them: `--warm`).

Prints a table and writes benchmarks/out/track_ab.json.
Run: python benchmarks/track_ab.py --a OLD_CHECKOUT [--b .] [--c OTHER] [--extra NAME=ARGS]
     [--repeats 3] [--duration 20] [--warm]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shlex
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np

from photoservo.fileio import write_text_atomic

OUT = Path(__file__).resolve().parent / "out" / "track_ab.json"


def _poll_cpu(pid: int, cpu: dict[int, float], order: list[int], stop: threading.Event) -> None:
    """CPU seconds of process `pid` and its descendants, polled every 0.25 s until `stop`."""
    import psutil

    try:
        me = psutil.Process(pid)
    except psutil.Error:
        return
    while not stop.wait(0.25):
        try:
            procs = [me, *me.children(recursive=True)]
        except psutil.Error:
            continue
        for p in procs:
            try:
                if p.pid not in cpu and "resource_tracker" in " ".join(p.cmdline()):
                    continue  # multiprocessing's own helper
                t = p.cpu_times()
            except psutil.Error:
                continue
            if p.pid not in cpu:
                order.append(p.pid)
            cpu[p.pid] = t.user + t.system


def run(tree: Path, module: str, extra: list[str], duration: float, cwd: str) -> dict:
    """One `track --sim` session of the checkout at `tree`, its summary and CPU seconds."""
    load = os.getloadavg()[0]
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    p = subprocess.Popen([sys.executable, "-m", module, "track", "--sim", "--duration", str(duration), "--json", *extra],
                         cwd=cwd, env=dict(os.environ, PYTHONPATH=str(tree)), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    cpu: dict[int, float] = {}
    order: list[int] = []
    stop = threading.Event()
    poll = threading.Thread(target=_poll_cpu, args=(p.pid, cpu, order, stop), daemon=True)
    poll.start()
    out, err = p.communicate()
    stop.set()
    poll.join()
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    try:
        d = json.loads(out)
    except json.JSONDecodeError:
        return {"exit": p.returncode, "error": err.strip().splitlines()[-1:] or ["no output"]}
    return {"exit": p.returncode, "load": load, "load_end": os.getloadavg()[0], "fps": d["frames"] / duration,
            "frames": d["frames"], "found": d["found_ratio"], "track_error_mm": d.get("track_error_mm"),
            "hold_error_rms_mm": d.get("hold_error_rms_mm", d.get("rms_position_error_mm")),
            "timings_ms": d["timings_ms_median"], "cpu_s": (r1.ru_utime + r1.ru_stime) - (r0.ru_utime + r0.ru_stime),
            "cpu_s_by_process": [cpu[q] for q in order]}


def medians(runs: list[dict]) -> dict:
    ok = [r for r in runs if "fps" in r]

    def med(f) -> float:
        vals = [f(r) for r in ok]
        vals = [np.nan if v is None else v for v in vals]
        return float(np.median(vals)) if vals else float("nan")
    out = {"runs": len(ok), "fps": med(lambda r: r["fps"]), "found": med(lambda r: r["found"]),
           "track_error_median_mm": med(lambda r: (r["track_error_mm"] or {}).get("median")),
           "track_error_p95_mm": med(lambda r: (r["track_error_mm"] or {}).get("p95")),
           "hold_error_rms_mm": med(lambda r: r["hold_error_rms_mm"]), "cpu_s": med(lambda r: r["cpu_s"])}
    for k in ("capture", "hue", "ga", "record", "frame", "control_ms"):
        out[f"{k}_ms"] = med(lambda r: r["timings_ms"].get(k))
    for i in range(6):  # the processes in start order (today: session, emulator, recorder, renderer, control, encoder)
        out[f"process_{i + 1}_cpu_s"] = med(lambda r: (r["cpu_s_by_process"] + [np.nan] * 6)[i])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a", required=True, help="the checkout to compare against (PATH or PATH:MODULE)")
    ap.add_argument("--b", default=str(Path(__file__).resolve().parent.parent), help="the checkout measured (this one)")
    ap.add_argument("--c", default=None, help="a third checkout (PATH or PATH:MODULE)")
    ap.add_argument("--extra", action="append", default=[], metavar="NAME=ARGS",
                    help="a variant of the last checkout with more track arguments, e.g. norec=--no-record")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--warm", action="store_true", help="one untimed short run of each first (compiles the kernels)")
    a = ap.parse_args()
    variants: dict[str, tuple[Path, str, list[str]]] = {}
    for name, spec in (("a", a.a), ("b", a.b), ("c", a.c)):
        if spec is not None:
            path, _, module = spec.partition(":")
            variants[name] = (Path(path).resolve(), module or "photoservo.cli", [])
    last = variants[list(variants)[-1]]
    for e in a.extra:
        name, _, args = e.partition("=")
        variants[name] = (last[0], last[1], shlex.split(args))
    runs: dict[str, list[dict]] = {name: [] for name in variants}
    with tempfile.TemporaryDirectory() as cwd:  # the recordings land in cwd/logs
        if a.warm:
            for tree, module, extra in variants.values():
                run(tree, module, extra, 1.0, cwd)
        for i in range(a.repeats):
            for name, (tree, module, extra) in variants.items():
                r = run(tree, module, extra, a.duration, cwd)
                runs[name].append(r)
                print(f"{name} {i}: " + json.dumps(r), flush=True)
    m = {name: medians(rs) for name, rs in runs.items()}
    print(f"medians of {a.repeats} runs of {a.duration:.0f} s each, alternately; "
          + "; ".join(f"{n} = {t} {mod} {' '.join(x)}" for n, (t, mod, x) in variants.items()))
    names = list(variants)
    print(f"{'':<28}" + "".join(f"{n:>12}" for n in names) + "".join(f"{n + ' / a':>12}" for n in names[1:]))
    for k in m["a"]:
        vals = [m[n][k] for n in names]
        print(f"{k:<28}" + "".join(f"{v:>12.2f}" for v in vals)
              + "".join(f"{(v / vals[0] if vals[0] else float('nan')):>12.2f}" for v in vals[1:]))
    OUT.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(OUT, json.dumps({"variants": {n: [str(t), mod, x] for n, (t, mod, x) in variants.items()},
                                       "duration_s": a.duration, "medians": m, "runs": runs}, indent=1, default=float))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
