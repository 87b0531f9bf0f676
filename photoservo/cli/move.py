"""photoservo move --port PORT (--joints J1 .. J7 | --home) [--speed PCT] [--rt-priority N]
                  [--record OUT.rrd | --no-record] [--config CFG.toml] [--set ...]

Moves the PA-10 to the given joint angles (degrees, order S1 S2 S3 E1 E2 W1 W2) or to the home
posture through the serial bridge: checks the target against the joint ranges (less the motion
margin) and the Cartesian keep-out, enables the servo, streams jerk-limited Ruckig setpoints
(servo/motion.py) at the control rate with a progress bar on stderr, then disables the servo.
Recorded to Rerun (logs/<time>_move.rrd by default): joint state, setpoints, events.

A target outside the limits or the keep-out is refused with a one-line error (exit 2) before
anything moves. Ctrl-C, SIGTERM or SIGHUP make a controlled stop, disable the servo and close the
link and the recording (exit 128+N: 130, 143, 129). A bridge that goes silent or away ends the
move with a one-line error (exit 3); the bridge's watchdog has already stopped the arm. A noisy
line (the link-quality gate, [link] max_*_per_s) ends it with a controlled stop, servo off and a
one-line error with the counts (exit 3); the progress bar shows the link quality while the arm
moves (on a terminal).

Examples:
    photoservo pa10-sim --link /tmp/pa10 &
    photoservo move --port /tmp/pa10 --joints 10 30 0 60 0 90 0 --speed 50
    photoservo move --port /tmp/pa10 --home
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import time

import numpy as np

from photoservo.cli.options import (
    add_config_options,
    add_recording_options,
    bounded,
    open_link,
    realtime_or_input_error,
    rt_priority,
)
from photoservo.cli.output import progress
from photoservo.cli.signals import report_stop, signal_name
from photoservo.config import load_config
from photoservo.errors import EXIT_HARDWARE, InputError
from photoservo.robot.clock import Rate
from photoservo.robot.link import Link, LinkError, LinkQuality
from photoservo.robot.pa10 import HOME_Q, JOINT_NAMES, load_limits
from photoservo.servo.motion import Motion
from photoservo.tomlconf import dump_config

log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--port", required=True,
                   help="bridge serial port or pyserial URL (the path pa10-sim prints; `photoservo find-port` lists them)")
    goal = p.add_mutually_exclusive_group(required=True)
    goal.add_argument("--joints", nargs=7, type=bounded(float, -360.0, 360.0, unit="deg"), metavar="J",
                      help="target joint angles S1 S2 S3 E1 E2 W1 W2 (deg)")
    goal.add_argument("--home", action="store_true", help="move to the home posture (pa10.HOME_Q)")
    p.add_argument("--speed", type=bounded(float, 0.0, 100.0, lo_open=True, unit="%"), metavar="PCT",
                   help="speed override, %% of the joint limits (default: [motion] speed_override_pct)")
    add_recording_options(p, "move")
    p.add_argument("--timeout", type=bounded(float, 0.0, 3600.0, lo_open=True, unit="s"), default=60.0, metavar="S",
                   help="stop the arm and give up after this long (s, default 60)")
    p.add_argument("--rt-priority", type=rt_priority, metavar="N",
                   help="run the control loop with SCHED_FIFO priority N (1..99; Linux, needs permission): "
                        "holds the 250 Hz period on a loaded machine (benchmarks/link.py)")
    add_config_options(p)


class _Progress:
    """Progress of the move on stderr (a tqdm bar, on a terminal only): share of the joint-space
    distance covered, in whole percent, and the link quality beside it."""

    def __init__(self, q0: np.ndarray, target: np.ndarray) -> None:
        self.q0, self.target = q0, target
        self.d0 = float(np.max(np.abs(target - q0))) or 1.0
        self.link = ""
        self.bar = progress(100, "move", unit="%", bar_format="{desc} {bar} {n:3.0f}% {elapsed} {postfix}")

    def update(self, q: np.ndarray, quality: LinkQuality, final: bool = False) -> None:
        frac = 1.0 - min(1.0, float(np.max(np.abs(self.target - q))) / self.d0)
        pct = 100 if final else min(99, int(100 * frac))
        link = quality.text()
        if link != self.link:
            self.link = link
            self.bar.set_postfix_str(link, refresh=False)
        if pct != self.bar.n:
            self.bar.update(pct - self.bar.n)

    def close(self) -> None:
        self.bar.close()


def parse_target(args: argparse.Namespace) -> np.ndarray:
    if args.home:
        return HOME_Q.copy()
    return np.radians(np.asarray(args.joints, float))


def _open_recorder(args: argparse.Namespace, cfg):
    if args.no_record:
        return None
    from photoservo.record.recorder import Recorder

    rec = Recorder.from_config(cfg.recording, "move", args.record)
    rec.log_static_setup(None, config_toml_text=dump_config(cfg))
    return rec


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config, args.overrides)
    limits = load_limits()
    motion = Motion(cfg.motion, limits)
    if args.speed is not None:
        motion.speed_override_pct = args.speed
    target = parse_target(args)
    motion.check_target(target)  # ranges less the margin, keep-out: before touching the port

    if args.rt_priority is not None:  # before the link's reader thread starts: it inherits it
        realtime_or_input_error(args.rt_priority)
    link = open_link(args.port, cfg.link, JOINT_NAMES)  # a missing port: exit 2; a silent or noisy one: 3
    version = link.version
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
        print(f"photoservo move: error: {e}{' ' + stopped if stopped else ''}", file=sys.stderr)
        if rec is not None:
            rec.event(time.monotonic(), f"link error: {e}", level="ERROR")
        return EXIT_HARDWARE
    finally:
        link.close()
        if rec is not None:
            rec.close()
            if rec.written:
                print(f"recording: {rec.path}")   # stdout: stderr keeps its one line


def _move(link: Link, motion: Motion, target: np.ndarray, rec, timeout: float) -> int:
    """Enable, stream Motion.move_step setpoints until done, disable. Ctrl-C, SIGTERM, SIGHUP:
    controlled stop, servo off, one line, exit 128+N."""
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
                rec.log_arm(s.t, s.q, sp.q, sp.dq)
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
        bar.close()
        link.disable()
        s = link.wait_until_still()
        err = np.degrees(np.abs(s.q - target))
        log.info(f"move: done, largest joint error {err.max():.3f} deg ({JOINT_NAMES[int(err.argmax())]}); "
                 f"setpoints sent {link.setpoints_sent}, refused {link.refused}, CRC errors {link.crc_errors}")
        if reasons:
            log.info("move: motion notes: " + "; ".join(f"{k} x{n}" for k, n in reasons.items()))
        if rec is not None:
            rec.event(s.t, f"move done, largest joint error {err.max():.3f} deg")
        return 0
    except KeyboardInterrupt as e:  # Ctrl-C, SIGTERM, SIGHUP (cli/signals.py)
        bar.close()
        link.stop()
        s = link.wait_until_still()
        link.disable()
        if rec is not None:
            rec.event(s.t, f"interrupted by {signal_name(e)}: controlled stop, servo off", level="WARN")
        return report_stop("move", e, "controlled stop, servo off")
    finally:
        bar.close()
