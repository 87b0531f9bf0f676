"""The simulator's bridge under load (issue 12): the longest gap between state reports that the
control process sees, with the emulator as a thread of a busy Python process (as `track --sim`
ran it before) or in its own prioritised process (sim/emulator_process.py, as it runs now).

The busy process holds the interpreter lock like the vision loop's Python work; two CPU hogs
(`python -c 'while 1: pass'`) run beside it; the link runs in a spawned process with the control
process's scheduling (robot/clock.raise_priority). A gap over [link] silence_timeout_s (0.25 s)
is the "bridge silent" fault of the issue. The machine is shared: the load is printed and stored.

    python benchmarks/sim_load.py [--seconds 10] [--repeat 3]   # table + benchmarks/out/sim_load.json
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

from photoservo.config import load_config
from photoservo.robot.pa10 import load_limits
from photoservo.sim.emulator import Emulator
from photoservo.sim.emulator_process import EmulatorProcess

OUT = Path(__file__).resolve().parents[1] / "benchmarks" / "out" / "sim_load.json"
CFG = load_config()


def _watch(path: str, seconds: float, conn) -> None:
    """In its own process, scheduled like the control process: the longest gap between states."""
    from photoservo.robot.clock import raise_priority
    from photoservo.robot.link import Link

    raise_priority(20)
    link = Link(path, CFG.link)
    link.open()
    worst, last, t_end = 0.0, time.monotonic(), time.monotonic() + seconds
    seen = link.wait_state().t_rx
    while time.monotonic() < t_end:
        hist = link.history()
        for s in hist:
            if s.t_rx > seen:
                worst, seen, last = max(worst, s.t_rx - last), s.t_rx, s.t_rx
        time.sleep(0.002)
    link.close()
    conn.send(worst)


def _busy(stop: threading.Event) -> None:
    """Pure-Python work holding the interpreter lock, like the vision loop's Python parts."""
    while not stop.is_set():
        sum(i * i for i in range(20000))


def run(kind: str, seconds: float) -> float:
    emu = Emulator(CFG.emulator, load_limits()) if kind == "thread" else EmulatorProcess(CFG.emulator, load_limits())
    path = emu.start()
    stop = threading.Event()
    busy = threading.Thread(target=_busy, args=(stop,), daemon=True)
    busy.start()
    ctx = multiprocessing.get_context("spawn")
    rx, tx = ctx.Pipe(duplex=False)
    p = ctx.Process(target=_watch, args=(path, seconds, tx))
    p.start()
    worst = rx.recv()
    p.join()
    stop.set()
    emu.stop()
    return worst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    hogs = [subprocess.Popen([sys.executable, "-c", "while 1: pass"]) for _ in range(2)]
    try:
        load0 = os.getloadavg()[0]
        res = {kind: [run(kind, args.seconds) for _ in range(args.repeat)] for kind in ("thread", "process")}
    finally:
        for h in hogs:
            h.kill()
    print(f"longest gap between state reports, {args.repeat} x {args.seconds:g} s beside 2 CPU hogs and a "
          f"busy Python thread, load average {load0:.1f} -> {os.getloadavg()[0]:.1f}")
    for kind, v in res.items():
        print(f"  emulator as a {kind:<8}: " + ", ".join(f"{1e3 * x:.0f} ms" for x in v)
              + f"   (silence limit {1e3 * CFG.link.silence_timeout_s:.0f} ms)")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps({"load_average": [load0, os.getloadavg()[0]], "seconds": args.seconds,
                               "worst_gap_ms": {k: [round(1e3 * x, 1) for x in v] for k, v in res.items()}},
                              indent=2))


if __name__ == "__main__":
    main()
