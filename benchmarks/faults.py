"""Fault timings for the README's fault table (issue 12): how long the host takes to notice each
link fault, over a real pty with the bridge emulator in this process (a thread), shipped
[link] and [emulator] settings.

- lost bridge: the emulator closes its pty -> LinkError ("went away"/"silent");
- silent bridge: the emulator stops talking, pty open -> LinkError ("silent");
- noisy line: 1 % of the bytes dropped and 1 % corrupted each way while the host holds the arm
  -> LinkQualityError (the link-quality gate);
- setpoint watchdog: the host stops sending mid-move -> first STOPPING report, bridge time
  after the last setpoint the bridge accepted.

Each is run --repeat times; the table gives the median and the worst. The machine is shared:
the load average is printed and stored.

    python benchmarks/faults.py [--repeat 5]      # table + benchmarks/out/faults.json
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from photoservo.config import load_config
from photoservo.robot import protocol as P
from photoservo.robot.link import Link, LinkError, LinkQualityError
from photoservo.sim.emulator import Emulator

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "out" / "faults.json"
CFG = load_config()
T = 1.0 / CFG.motion.rate_hz


def _hold(link: Link, q: np.ndarray, until) -> float:
    """Stream "hold at q" with state reads until `until()` raises; return the time it raised."""
    t_next = time.monotonic()
    while True:
        link.send_setpoint(q, np.zeros(7))
        link.state()
        until()
        t_next += T
        time.sleep(max(0.0, t_next - time.monotonic()))


def lost_or_silent(lost: bool) -> float:
    with Emulator(CFG.emulator) as emu:
        link = Link(emu.path, CFG.link)
        link.open()
        link.wait_state()
        t0 = time.monotonic()
        if lost:
            emu.stop()
        else:
            emu.silence(True)
        try:
            while True:
                link.state()
                time.sleep(0.002)
        except LinkError:
            dt = time.monotonic() - t0
        link.close()
        return dt


def noisy_line() -> float:
    with Emulator(CFG.emulator) as emu, Link(emu.path, CFG.link) as link:
        link.enable()
        q = link.wait_state().q
        t0 = [0.0]

        def turn_noisy():
            if not t0[0] and time.monotonic() - t_start > 0.3:
                emu.line_faults(drop=0.01, corrupt=0.01)
                t0[0] = time.monotonic()

        t_start = time.monotonic()
        try:
            _hold(link, q, turn_noisy)
        except LinkQualityError:
            dt = time.monotonic() - t0[0]
        emu.line_faults(0.0, 0.0)
        return dt


def watchdog() -> float:
    with Emulator(CFG.emulator) as emu, Link(emu.path, CFG.link) as link:
        link.enable()
        q = link.wait_state().q.copy()
        v = np.zeros(7)
        v[0] = 0.2  # rad/s on S1
        t_next = time.monotonic()
        for _ in range(int(0.5 / T)):
            q = q + v * T
            link.send_setpoint(q, v)
            t_next += T
            time.sleep(max(0.0, t_next - time.monotonic()))
        t_last = link.wait_state().report.t_host_echo_us * 1e-6  # the last accepted setpoint
        time.sleep(0.2)
        first = next(s for s in link.history() if s.status & P.Status.STOPPING)
        return first.t - t_last


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    load0 = os.getloadavg()[0]
    runs = {"lost bridge -> LinkError": [lost_or_silent(True) for _ in range(args.repeat)],
            "silent bridge -> LinkError": [lost_or_silent(False) for _ in range(args.repeat)],
            "noisy line (1 % drop + 1 % corrupt) -> quality gate": [noisy_line() for _ in range(args.repeat)],
            "setpoints cease -> bridge watchdog stop": [watchdog() for _ in range(args.repeat)]}
    rows = {k: {"median_ms": 1e3 * float(np.median(v)), "max_ms": 1e3 * float(np.max(v)),
                "runs_ms": [round(1e3 * x, 1) for x in v]} for k, v in runs.items()}
    print(f"fault timings, {args.repeat} runs each, load average {load0:.1f} -> {os.getloadavg()[0]:.1f}")
    for k, r in rows.items():
        print(f"  {k:<55} median {r['median_ms']:7.1f} ms   worst {r['max_ms']:7.1f} ms")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps({"load_average": [load0, os.getloadavg()[0]], "repeat": args.repeat,
                               "silence_timeout_s": CFG.link.silence_timeout_s,
                               "watchdog_periods": CFG.emulator.watchdog_periods, "faults": rows}, indent=2))


if __name__ == "__main__":
    main()
