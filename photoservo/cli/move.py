"""photoservo move --port PORT (--joints J1 .. J7 | --home) [--speed PCT] [--rt-priority N]
                  [--record OUT.rrd | --no-record] [--config CFG.toml] [--set ...]

Moves the PA-10 to the given joint angles (degrees, order S1 S2 S3 E1 E2 W1 W2) or to the home
posture through the serial bridge: checks the target against the joint ranges (less the motion
margin) and the Cartesian keep-out, enables the servo, streams jerk-limited Ruckig setpoints
(servo/motion.py) at the control rate with a progress bar on stderr, then disables the servo.
Recorded to Rerun (logs/<time>_move.rrd by default): joint state, setpoints, events.

A target outside the limits or the keep-out is refused with a one-line error (exit 2) before
anything moves. Ctrl-C makes a controlled stop, disables the servo and closes the link (exit
130). A bridge that goes silent or away ends the move with a one-line error (exit 3); the
bridge's watchdog has already stopped the arm. A noisy line (the link-quality gate, [link]
max_*_per_s) ends it with a controlled stop, servo off and a one-line error with the counts
(exit 3); the progress line shows the link quality while the arm moves.

Example:
    photoservo pa10-sim --link /tmp/pa10 &
    photoservo move --port /tmp/pa10 --joints 10 30 0 60 0 90 0 --speed 50
    photoservo move --port /tmp/pa10 --home
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from photoservo.errors import InputError
from photoservo.robot.clock import Rate
from photoservo.robot.link import Link, LinkError, LinkQuality, LinkQualityError
from photoservo.robot.pa10 import HOME_Q, JOINT_NAMES, load_limits
from photoservo.cli.config import add_config_options
from photoservo.cli.pa10_sim import realtime_or_input_error
from photoservo.config import load_config
from photoservo.servo.motion import Motion
from photoservo.tomlconf import dump_config


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--port", required=True, help="bridge serial port or pyserial URL (e.g. the path pa10-sim prints)")
    goal = p.add_mutually_exclusive_group(required=True)
    goal.add_argument("--joints", nargs=7, type=float, metavar="J", help="target joint angles S1 .. W2 (deg)")
    goal.add_argument("--home", action="store_true", help="move to the home posture (pa10.HOME_Q)")
    p.add_argument("--speed", type=float, metavar="PCT", help="speed override 1..100 %% (default: [motion] speed_override_pct)")
    rec = p.add_mutually_exclusive_group()
    rec.add_argument("--record", metavar="OUT.rrd", help="recording path (default logs/<UTC time>_move.rrd)")
    rec.add_argument("--no-record", action="store_true", help="do not record to Rerun")
    p.add_argument("--timeout", type=float, default=60.0, metavar="S", help="give up after this long (s, default 60)")
    p.add_argument("--rt-priority", type=int, metavar="N",
                   help="run the control loop with SCHED_FIFO priority N (1..99; Linux, needs permission): "
                        "holds the 250 Hz period on a loaded machine (benchmarks/link.py)")
    add_config_options(p)


class _Progress:
    """One-line progress bar on stderr: share of the joint-space distance covered."""

    def __init__(self, q0: np.ndarray, target: np.ndarray, width: int = 30) -> None:
        self.q0, self.target, self.width = q0, target, width
        self.d0 = float(np.max(np.abs(target - q0))) or 1.0
        self.shown: tuple[int, str] | None = None
        self.length = 0  # of the line last written (a shorter one is padded over it)
        self.t0 = time.monotonic()

    def update(self, q: np.ndarray, quality: LinkQuality, final: bool = False) -> None:
        frac = 1.0 - min(1.0, float(np.max(np.abs(self.target - q))) / self.d0)
        pct = 100 if final else min(99, int(100 * frac))
        link = quality.text()
        if (pct, link) == self.shown:
            return
        self.shown = (pct, link)
        k = self.width * pct // 100
        line = f"move [{'#' * k}{'.' * (self.width - k)}] {pct:3d}% {time.monotonic() - self.t0:5.1f}s {link}"
        sys.stderr.write("\r" + line.ljust(self.length))
        self.length = len(line)
        if final:
            sys.stderr.write("\n")
        sys.stderr.flush()


def parse_target(args: argparse.Namespace) -> np.ndarray:
    if args.home:
        return HOME_Q.copy()
    q = np.radians(np.asarray(args.joints, float))
    if not np.all(np.isfinite(q)):
        raise InputError(f"--joints {' '.join(map(str, args.joints))}: every angle must be a finite number")
    return q


def _open_recorder(args: argparse.Namespace, cfg):
    if args.no_record:
        return None
    from photoservo.record.recorder import Recorder

    rec = Recorder.open(args.record, "move", mode=cfg.recording.mode, segment_s=cfg.recording.segment_s,
                        logs_dir=cfg.recording.dir)
    rec.log_static_setup(None, config_toml_text=dump_config(cfg))
    return rec


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config, args.overrides)
    limits = load_limits()
    motion = Motion(cfg.motion, limits)
    if args.speed is not None:
        if not 0.0 < args.speed <= 100.0:
            raise InputError(f"--speed {args.speed:g}: must be within 1..100 %")
        motion.speed_override_pct = args.speed
    if args.timeout <= 0:
        raise InputError(f"--timeout {args.timeout:g}: must be > 0 s")
    target = parse_target(args)
    motion.check_target(target)  # ranges less the margin, keep-out: before touching the port

    if args.rt_priority is not None:  # before the link's reader thread starts: it inherits it
        realtime_or_input_error(args.rt_priority)
    link = Link(args.port, cfg.link, JOINT_NAMES)
    try:
        version = link.open()
    except LinkQualityError as e:  # a bridge answered through a noisy line: a link failure
        print(f"photoservo move: error: {e}", file=sys.stderr)
        return 3
    except LinkError as e:
        raise InputError(f"--port {args.port}: {e}") from None
    rec = None
    try:
        for j, n in enumerate(JOINT_NAMES):  # the bridge's own ranges must allow the target too
            if not version.q_min[j] <= target[j] <= version.q_max[j]:
                raise InputError(f"target: joint {n} = {math.degrees(target[j]):.2f} deg is outside the "
                                 f"bridge's range [{math.degrees(version.q_min[j]):.1f}, "
                                 f"{math.degrees(version.q_max[j]):.1f}] deg")
        s = link.wait_state()
        motion.check_target(target, q_start=s.q)  # and the path from here
        rec = _open_recorder(args, cfg)
        return _move(link, motion, target, rec, args.timeout)
    except LinkError as e:
        stopped = link.safe_stop(timeout=2.0)  # a noisy line still carries STOP and servo off
        sys.stderr.write("\n" if link.setpoints_sent else "")
        print(f"photoservo move: error: {e}{' ' + stopped if stopped else ''}", file=sys.stderr)
        if rec is not None:
            rec.event(time.monotonic(), f"link error: {e}", level="ERROR")
        return 3
    finally:
        link.close()
        if rec is not None:
            rec.close()


def _move(link: Link, motion: Motion, target: np.ndarray, rec, timeout: float) -> int:
    """Enable, stream Motion.move_step setpoints until done, disable. Ctrl-C: controlled stop."""
    link.enable()
    s = link.wait_state()
    bar = _Progress(s.q, target)
    if rec is not None:
        rec.event(s.t, f"move to {np.round(np.degrees(target), 3).tolist()} deg, speed "
                       f"{motion.speed_override_pct:g} %")
    rate = Rate(motion.params.rate_hz)
    t_end = time.monotonic() + timeout
    last_reason = ""
    reasons: dict[str, int] = {}  # what the motion safety layer did, and how often
    try:
        while True:
            s = link.state()
            sp = motion.move_step(s.q, s.dq, target)
            link.send_setpoint(sp.q, sp.dq)
            if rec is not None:
                rec.log_arm(s.t, s.q, sp.q, sp.q)
            if sp.reason and sp.reason != last_reason:
                kind = sp.reason.split(" (")[0]
                reasons[kind] = reasons.get(kind, 0) + 1
                if rec is not None:
                    rec.event(s.t, sp.reason, level="WARN")
            last_reason = sp.reason
            bar.update(s.q, link.quality())
            if motion.done:
                break
            if time.monotonic() > t_end:
                link.stop()
                link.wait_until_still()
                link.disable()
                raise LinkError(f"move not finished after {timeout:g} s (last: {sp.reason or 'moving'}); stopped")
            rate.sleep()
        bar.update(s.q, link.quality(), final=True)
        link.disable()
        s = link.wait_until_still()
        err = np.degrees(np.abs(s.q - target))
        print(f"move: done, largest joint error {err.max():.3f} deg ({JOINT_NAMES[int(err.argmax())]}); "
              f"setpoints sent {link.setpoints_sent}, refused {link.refused}, "
              f"CRC errors {link.crc_errors}", file=sys.stderr)
        if reasons:
            print("move: motion notes: " + "; ".join(f"{k} x{n}" for k, n in reasons.items()), file=sys.stderr)
        if rec is not None:
            rec.event(s.t, f"move done, largest joint error {err.max():.3f} deg")
        return 0
    except KeyboardInterrupt:
        sys.stderr.write("\nmove: interrupted: controlled stop\n")
        link.stop()
        s = link.wait_until_still()
        link.disable()
        if rec is not None:
            rec.event(s.t, "interrupted by Ctrl-C: controlled stop, servo off", level="WARN")
        return 130
