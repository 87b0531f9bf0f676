"""Serial link to the PA-10 bridge: throughput, latency, control-loop jitter, fault safety
(issue 3 item 8).

    python benchmarks/link.py [--seconds 8] [--repeats 3] [--quick]

The bridge is the controller emulator as a separate process (`photoservo pa10-sim`, like the
real bridge on its own hardware), on a real pty, pacing bytes at the given baud rate.

1. Link (921600 and 115200 baud pacing):
   - max setpoint rate: "hold" setpoints written as fast as the line takes them (non-blocking
     writes; a setpoint that finds the line busy is dropped and not counted), confirmed by the
     bridge (the last state echoes the last setpoint's sequence number, no NACK);
   - a 250 Hz stream: setpoints the host got onto the line per second, state reports per second;
   - setpoint -> state round trip: host time from sending a setpoint to receiving the first
     state report that echoes it (includes waiting for the bridge's next 4 ms control tick).
2. Control-loop period at 250 Hz (`robot/clock.Rate`; each period: latest state ->
   Motion.move_step (Ruckig + safety layer) -> send_setpoint), shipped watchdog (3 periods):
   alone; next to a numpy/OpenCV thread (blur, HSV, matmul on 640x480 stereo); next to the real
   GA (`vision.estimator.estimate` on examples/scene, in a loop); next to a thread logging
   640x480 stereo frames at 30 fps to Rerun (`record.recorder.Recorder`, default mode); and with
   the GA + Rerun load in the main process but control + link in their OWN process
   (multiprocessing). Period error = |actual period - 4 ms|: p50, p99, max; watchdog firings
   (rising edges of the WATCHDOG status bit) and refused setpoints.
3. Faults: the bridge drops and corrupts bytes both ways while the host streams "hold here" at
   250 Hz: CRC failures counted on both sides, and whether any joint moved.

Each number is the median over --repeats runs. The machine has 2 cores shared with several
other jobs: the load average is printed and stored with the results.

Prints a table and writes benchmarks/out/link.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import multiprocessing as mp
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Self

import numpy as np

from photoservo.fileio import write_text_atomic
from photoservo.robot import protocol as P
from photoservo.robot.clock import Rate, set_realtime
from photoservo.robot.link import Link, LinkError, LinkParams
from photoservo.robot.pa10 import HOME_Q, load_limits
from photoservo.tomlconf import build_dataclass, configs_dir, read_toml

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "out" / "link.json"
DEFAULTS = read_toml(configs_dir() / "default.toml")
LINK = build_dataclass(LinkParams, DEFAULTS["link"], "link")
HZ = 250.0
T = 1.0 / HZ


# ----------------------------------------------------------------------------- the bridge


class Bridge:
    """`photoservo pa10-sim` in its own process; `path` is its pty."""

    def __init__(self, *flags: str) -> None:
        # real-time priority when permitted: the real bridge is dedicated hardware, so its
        # emulator must not be what starves on this shared machine
        # (below the control process's 40: here both share 2 busy cores, which they would not)
        rt = ["--rt-priority", "30"] if _rt_permitted() else []
        self.p = subprocess.Popen([sys.executable, "-m", "photoservo.cli", "pa10-sim", *rt, *flags],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.path = self.p.stdout.readline().strip()
        if not self.path.startswith("/dev/"):
            raise SystemExit(f"pa10-sim did not start: {self.p.stderr.read()}")

    def close(self) -> str:
        self.p.send_signal(signal.SIGTERM)
        _, err = self.p.communicate(timeout=10)
        return err.strip().splitlines()[-1] if err.strip() else ""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        if self.p.poll() is None:
            self.close()


# ----------------------------------------------------------------------------- 1. link


def link_numbers_rt(baud: int, seconds: float) -> dict:
    """`link_numbers` in a spawned process, real-time when permitted: part 1 measures the line
    and the bridge, not how long this shared machine keeps a normal process waiting."""
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe(duplex=False)
    p = ctx.Process(target=_link_numbers_in_process, args=(baud, seconds, child, _rt_permitted()))
    p.start()
    res = parent.recv()
    p.join(timeout=10)
    if "error" in res:
        raise SystemExit(f"link measurement at {baud} baud failed: {res['error']}")
    return res


def _link_numbers_in_process(baud: int, seconds: float, conn, rt: bool) -> None:
    if rt:
        set_realtime(40)
    try:
        res = link_numbers(baud, seconds)
        res["host_realtime"] = rt
        conn.send(res)
    except Exception as e:  # noqa: BLE001 - report to the parent instead of dying silently
        conn.send({"error": repr(e)})


def link_numbers(baud: int, seconds: float) -> dict:
    with Bridge("--baud", str(baud)) as br, Link(br.path, dataclasses.replace(LINK, baud=baud)) as lk:
        lk.enable()
        q0 = lk.wait_state().q
        zero = np.zeros(7)
        # max setpoint rate: as fast as the line takes them
        sent0, t0 = lk.setpoints_sent, time.monotonic()
        while time.monotonic() - t0 < seconds / 2:
            if lk.send_setpoint(q0, zero) is None:
                time.sleep(0.0002)
        dt = time.monotonic() - t0
        n_max = lk.setpoints_sent - sent0
        last_seq = lk._seq
        confirmed = _wait(lambda: lk.wait_state().report.setpoint_seq == last_seq, 2.0)
        max_rate = n_max / dt if confirmed and not lk.nacks else float("nan")
        time.sleep(0.05)
        # a 250 Hz stream with latency
        sent0, drop0 = lk.setpoints_sent, lk.setpoints_dropped
        stamps: dict[int, float] = {}
        rate = Rate(HZ)
        states = []
        seen_t_rx = 0.0
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds / 2:
            t = time.monotonic()
            seq = lk.send_setpoint(q0, zero, t_host=t)
            if seq is not None:
                stamps[int(t * 1e6)] = t
            for s in lk.history():
                if s.t_rx > seen_t_rx:
                    states.append(s)
                    seen_t_rx = s.t_rx
            rate.sleep()
        dt = time.monotonic() - t0
        n_sent = lk.setpoints_sent - sent0
        n_drop = lk.setpoints_dropped - drop0
        time.sleep(0.05)
        for s in lk.history():
            if s.t_rx > seen_t_rx:
                states.append(s)
                seen_t_rx = s.t_rx
        lat = []
        echoed = set()
        for s in states:
            e = s.report.t_host_echo_us
            if e in stamps and e not in echoed:
                echoed.add(e)
                lat.append(s.t_rx - stamps[e])
        n_states = sum(1 for s in states if s.t_rx >= t0 + 0.05)
        lat_ms = 1e3 * np.array(lat) if lat else np.array([np.nan])
        out = {
            "baud": baud,
            "max_setpoint_rate_hz": max_rate,
            "stream_250hz_sent_hz": n_sent / dt,
            "stream_250hz_dropped_line_busy": n_drop,
            "state_rate_hz": n_states / (dt - 0.05),
            "roundtrip_ms_p50": float(np.percentile(lat_ms, 50)),
            "roundtrip_ms_p99": float(np.percentile(lat_ms, 99)),
            "roundtrip_ms_max": float(np.max(lat_ms)),
            "nacks": len(lk.nacks),
            "host_crc_errors": lk.crc_errors,
        }
        lk.stop()
        lk.wait_until_still()
    return out


# ----------------------------------------------------------------------------- 2. control loop


def control_loop(path: str, seconds: float) -> dict:
    """The 250 Hz loop: state -> Motion.move_step -> setpoint; alternating between two targets."""
    from photoservo.config import load_config
    from photoservo.servo.motion import Motion

    cfg = load_config()
    motion = Motion(cfg.motion, load_limits())
    targets = [HOME_Q + np.radians([15, -8, 10, 12, -15, 10, 20]), HOME_Q.copy()]
    wakes, steps_ms, late_ms = [], [], []
    watchdog_edges, was_wd = 0, False
    link_error = ""
    lk = Link(path, LINK)
    lk.open()
    try:
        lk.enable()
        lk.wait_state()
        k = 0
        rate = Rate(HZ)
        t_end = time.monotonic() + seconds
        while True:
            now = time.monotonic()
            wakes.append(now)
            if now > t_end:
                break
            s = lk.state()
            wd = bool(s.status & P.Status.WATCHDOG)
            watchdog_edges += wd and not was_wd
            was_wd = wd
            t0 = time.perf_counter()
            sp = motion.move_step(s.q, s.dq, targets[k % 2])
            steps_ms.append(1e3 * (time.perf_counter() - t0))
            lk.send_setpoint(sp.q, sp.dq)
            if motion.done:
                k += 1
            late_ms.append(1e3 * rate.sleep())
    except LinkError as e:  # the loop starved so long that the link declared the bridge silent
        link_error = str(e)
    nacks = [P.Error(n.error).name for n in lk.nacks]  # the last 64, for their kinds
    n_refused = lk.refused
    try:
        if not link_error:
            lk.stop()
            lk.wait_until_still()
            lk.disable()
    finally:
        lk.close()
    period = np.diff(wakes) if len(wakes) > 1 else np.array([np.nan])
    steps_ms, late_ms = steps_ms or [np.nan], late_ms or [np.nan]
    err_ms = 1e3 * np.abs(period - T)
    return {
        "periods": int(period.size),
        "period_err_ms_p50": float(np.percentile(err_ms, 50)),
        "period_err_ms_p99": float(np.percentile(err_ms, 99)),
        "period_err_ms_max": float(np.max(err_ms)),
        "period_over_12ms": int(np.sum(period > 3 * T)),
        "watchdog_firings": int(watchdog_edges),
        "refused_setpoints": n_refused,
        "refusals": sorted(set(nacks)),
        "moves_done": k,
        "link_lost": int(bool(link_error)),
        "link_error": link_error,
        "motion_step_ms_p50": float(np.median(steps_ms)),
        "motion_step_ms_p99": float(np.percentile(steps_ms, 99)),
        "motion_step_ms_max": float(np.max(steps_ms)),
        "late_wakeups_ms_p99": float(np.percentile(late_ms, 99)),
    }


@functools.cache
def _rt_permitted() -> bool:
    """Whether a process of ours may take SCHED_FIFO (tried in a throwaway child)."""
    code = "import os; os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))"
    return subprocess.run([sys.executable, "-c", code], check=False, capture_output=True).returncode == 0


def _control_in_process(path: str, seconds: float, conn, rt: bool, switch_s: float | None) -> None:
    if rt:  # before the link's reader thread starts, so that it inherits the policy
        set_realtime(40)
    if switch_s is not None:
        sys.setswitchinterval(switch_s)
    try:
        conn.send(control_loop(path, seconds))
    except Exception as e:  # noqa: BLE001 - report to the parent instead of dying silently
        conn.send({"error": repr(e)})


# ----------------------------------------------------------------------------- loads


def load_numpy_opencv(stop: threading.Event) -> None:
    """Stand-in vision work: blur + HSV of a 640x480 stereo pair and a 300x300 matmul."""
    import cv2

    rng = np.random.default_rng(0)
    imgs = [rng.integers(0, 255, (480, 640, 3), np.uint8) for _ in range(2)]
    a = rng.standard_normal((300, 300))
    while not stop.is_set():
        for im in imgs:
            cv2.cvtColor(cv2.GaussianBlur(im, (31, 31), 0), cv2.COLOR_BGR2HSV)
        a = np.tanh(a @ a.T / 300.0)


def load_ga(stop: threading.Event) -> None:
    """The real GA: the estimator on the bundled example scene, over and over."""
    from photoservo.fileio import read_image
    from photoservo.config import load_config
    from photoservo.vision.estimator import estimate
    from photoservo.vision.photo_model import load_photo_model
    from photoservo.vision.rig import load_rig

    cfg = load_config()
    scene = ROOT / "examples" / "scene"
    model = load_photo_model(str(scene / "photo.png"), cfg.photo_model, None)
    rig = load_rig(str(scene / "rig.toml"))
    left, right = read_image(scene / "left.png"), read_image(scene / "right.png")
    seed = 0
    while not stop.is_set():
        estimate(model, left, right, rig, cfg.ga, cfg.estimator, cfg.fitness, seed=seed)
        seed += 1


def load_rerun(stop: threading.Event) -> None:
    """A thread logging 640x480 stereo frames to Rerun at 30 fps (the default [recording] mode,
    as `track` does)."""
    from photoservo.config import load_config
    from photoservo.record.recorder import Recorder

    cfg = load_config()
    rng = np.random.default_rng(1)
    frames = [rng.integers(0, 255, (480, 640, 3), np.uint8) for _ in range(4)]
    with tempfile.TemporaryDirectory() as d, \
            Recorder.from_config(cfg.recording, "bench", Path(d) / "bench.rrd") as rec:
        rate = Rate(30.0)
        k = 0
        while not stop.is_set():
            rec.log_frame(k, time.monotonic(), frames[k % 4], frames[(k + 1) % 4])
            k += 1
            rate.sleep()


def with_loads(loads, fn):
    stop = threading.Event()
    threads = [threading.Thread(target=f, args=(stop,), daemon=True) for f in loads]
    for t in threads:
        t.start()
    time.sleep(2.0 if load_ga in loads else 0.5)  # let the GA get past its first (JIT-cached) call
    try:
        return fn()
    finally:
        stop.set()
        for t in threads:
            t.join(timeout=30)


def run_condition(name: str, loads, own_process: bool, seconds: float, rt: bool = False,
                  switch_s: float | None = None) -> dict:
    old_switch = sys.getswitchinterval()
    if switch_s is not None:
        sys.setswitchinterval(switch_s)
    try:
        return _run_condition(name, loads, own_process, seconds, rt, switch_s)
    finally:
        sys.setswitchinterval(old_switch)


def _run_condition(name: str, loads, own_process: bool, seconds: float, rt: bool,
                   switch_s: float | None) -> dict:
    with Bridge() as br:
        if own_process:
            ctx = mp.get_context("spawn")
            parent, child = ctx.Pipe(duplex=False)

            def fn():
                p = ctx.Process(target=_control_in_process, args=(br.path, seconds, child, rt, switch_s))
                p.start()
                res = parent.recv()
                p.join(timeout=10)
                return res
        else:
            def fn():
                return control_loop(br.path, seconds)
        res = with_loads(loads, fn)
        res["bridge"] = br.close()
    res["condition"] = name
    return res


# ----------------------------------------------------------------------------- 3. faults


def fault_run(seconds: float, drop: float, corrupt: float) -> dict:
    lim = load_limits()
    assert lim is not None
    with Bridge("--drop", str(drop), "--corrupt", str(corrupt), "--seed", "7") as br:
        # the link-quality gate wide open: this run measures what the bridge does with bad frames
        lk = Link(br.path, dataclasses.replace(LINK, ack_timeout_s=2.0, silence_timeout_s=1.0, max_bad_frames_per_s=1000.0,
                                               max_refused_per_s=1000.0, max_watchdog_per_s=1000.0))
        for _ in range(10):
            try:
                lk.open()
                break
            except ConnectionError:
                time.sleep(0.1)
        with lk:
            for _ in range(10):
                try:
                    lk.enable()
                    break
                except ConnectionError:
                    pass
            q0 = np.float32(lk.wait_state().q).astype(float)
            moved = 0.0
            rate = Rate(HZ)
            t_end = time.monotonic() + seconds
            seen = 0.0
            n_states = 0
            while time.monotonic() < t_end:
                lk.send_setpoint(q0, np.zeros(7))
                for s in lk.history():
                    if s.t_rx > seen:
                        seen = s.t_rx
                        n_states += 1
                        moved = max(moved, float(np.max(np.abs(s.q - q0))))
                rate.sleep()
            last = lk.wait_state().report
            host_crc = lk.crc_errors
            lk._servo_requested = False  # no stop/disable handshake needed: holding still
        summary = br.close()
    return {"drop": drop, "corrupt": corrupt, "seconds": seconds, "states_received": n_states,
            "host_crc_errors": host_crc, "bridge_rx_dropped_frames": last.rx_crc_errors,
            "max_joint_motion_rad": moved, "bridge": summary}


# ----------------------------------------------------------------------------- main


def _wait(pred, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.01)
    return False


def _median(runs: list[dict]) -> dict:
    out = dict(runs[0])
    for k, v in runs[0].items():
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            vals = [r[k] for r in runs if isinstance(r.get(k), (int, float))]
            out[k] = float(np.nanmedian(vals)) if vals else v
    out["runs"] = runs
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=8.0, help="length of each run (s)")
    ap.add_argument("--repeats", type=int, default=3, help="runs per number (median reported)")
    ap.add_argument("--quick", action="store_true", help="2 s runs, 1 repeat (a smoke test)")
    ap.add_argument("--only", metavar="TEXT", help="run only the control-loop conditions whose name has TEXT "
                    "(skips parts 1 and 3; does not write the JSON)")
    args = ap.parse_args()
    if args.quick:
        args.seconds, args.repeats = 2.0, 1
    load0 = os.getloadavg()
    result: dict = {"machine": {"cpus": os.cpu_count(), "loadavg_start": load0,
                                "note": "2-core machine shared with other jobs; numbers pessimistic"},
                    "seconds": args.seconds, "repeats": args.repeats}

    print("1. link over a pty, bridge emulator in its own process (host and bridge SCHED_FIFO when "
          "permitted)", flush=True)
    result["link"] = []
    for baud in () if args.only else (921600, 115200):
        r = _median([link_numbers_rt(baud, args.seconds) for _ in range(args.repeats)])
        result["link"].append(r)
        print(f"  {baud:>7} baud: max setpoint rate {r['max_setpoint_rate_hz']:7.1f} Hz | 250 Hz stream: sent "
              f"{r['stream_250hz_sent_hz']:6.1f}/s, states {r['state_rate_hz']:6.1f}/s | round trip ms "
              f"p50 {r['roundtrip_ms_p50']:5.2f} p99 {r['roundtrip_ms_p99']:6.2f} max {r['roundtrip_ms_max']:6.2f}"
              f" | nacks {r['nacks']:.0f}", flush=True)

    print("2. control loop at 250 Hz (period error = |period - 4 ms|), bridge at 921600 baud", flush=True)
    rt = _rt_permitted()
    result["bridge_realtime"] = rt
    conditions = [
        ("alone (thread)", [], False, {}),
        ("+ numpy/OpenCV thread", [load_numpy_opencv], False, {}),
        ("+ GA thread (estimator)", [load_ga], False, {}),
        ("+ Rerun stereo logging thread", [load_rerun], False, {}),
        ("+ GA + Rerun threads", [load_ga, load_rerun], False, {}),
        ("+ GA + Rerun threads, switch 0.5 ms", [load_ga, load_rerun], False, {"switch_s": 0.0005}),
        ("+ GA + Rerun, control own process", [load_ga, load_rerun], True, {}),
    ]
    if rt:
        conditions.append(("+ GA + Rerun, own process SCHED_FIFO", [load_ga, load_rerun], True, {"rt": True}))
    if args.only:
        conditions = [c for c in conditions if args.only in c[0]]
    result["control"] = []
    print(f"  {'condition':<38} {'p50':>6} {'p99':>6} {'max':>7} {'>12ms':>6} {'wdog':>5} {'nack':>5} "
          f"{'step p99':>8} {'lost':>4}  (ms; lost = runs whose link timed out)")
    for name, loads, own, kw in conditions:
        r = _median([run_condition(name, loads, own, args.seconds, **kw) for _ in range(args.repeats)])
        result["control"].append(r)
        if "error" in r:
            print(f"  {name:<38} error: {r['error']}")
            continue
        print(f"  {name:<38} {r['period_err_ms_p50']:6.2f} {r['period_err_ms_p99']:6.2f} "
              f"{r['period_err_ms_max']:7.2f} {r['period_over_12ms']:6.0f} {r['watchdog_firings']:5.0f} "
              f"{r['refused_setpoints']:5.0f} {r['motion_step_ms_p99']:8.2f} "
              f"{sum(x['link_lost'] for x in r['runs']):4d}", flush=True)

    print("3. line faults (both directions), host streaming 'hold' at 250 Hz", flush=True)
    result["faults"] = []
    for drop, corrupt in () if args.only else ((0.0005, 0.001), (0.002, 0.005)):
        r = fault_run(args.seconds, drop, corrupt)
        result["faults"].append(r)
        print(f"  drop {drop:<7g} corrupt {corrupt:<7g}: host CRC/frame errors {r['host_crc_errors']}, bridge "
              f"dropped frames {r['bridge_rx_dropped_frames']}, largest joint motion "
              f"{r['max_joint_motion_rad']:.2e} rad", flush=True)

    result["machine"]["loadavg_end"] = os.getloadavg()
    print(f"load average start {load0[0]:.2f}, end {result['machine']['loadavg_end'][0]:.2f} "
          f"on {os.cpu_count()} CPUs (shared machine)")
    if args.only:
        return 0
    write_text_atomic(OUT, json.dumps(result, indent=1, default=float) + "\n")
    print(f"wrote {OUT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
