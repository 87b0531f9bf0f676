"""photoservo track [--sim] [--duration S] [--no-motion] [--collect] [--lockstep]
                   [--rig RIG.toml --photo PHOTO --port PORT]  (hardware)
                   [--record OUT.rrd | --no-record] [--view | --connect URL]
                   [--config CFG.toml] [--set key=value ...] [--seed N] [--json]

The main job: stereo frames -> a few GA generations per frame (vision/tracker.py) -> servo law
(servo/control.py) -> Ruckig (servo/motion.py) -> serial link -> the PA-10, recorded to Rerun
(logs/<UTC time>_track.rrd by default).

With --sim (the default when no cameras ([cameras] kind) or --port are configured) it starts
the controller emulator on a pty and the simulated world (sim/world.py): a creature drifting,
heaving and rolling on the water, the stereo cameras on the simulated arm's flange. With
`--lockstep` (or `--set sim.lockstep=true`) the simulation runs on its own clock instead of
real time: slower than real time on this machine, but deterministic.

The arm is enabled at start and disabled at exit; --no-motion tracks without commanding it.
Live status on stderr. Ctrl-C, SIGTERM or SIGHUP stop the arm in a controlled way, switch the
servo off and close the recording (exit 130, 143, 129); a link fault stops it too (exit 3).

Examples:
    photoservo track --sim --duration 20
    photoservo track --sim --duration 20 --collect --set sim.drift_mm_s=[20.0,10.0]
    photoservo track --sim --world-from logs/X_track.rrd --set servo.k_position=1.0   # same world, new gain
    photoservo track --rig rig.toml --photo squid.jpg --port /dev/ttyUSB0 --cameras 0 1
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import math
import os
import sys
from pathlib import Path

from photoservo import __version__
from photoservo.errors import EXIT_HARDWARE, InputError
from photoservo.cli.options import add_config_options, bounded, check_display, rt_priority, seed
from photoservo.cli.output import dumps_strict
from photoservo.cli.signals import report_stop
from photoservo.config import load_config
from photoservo.tomlconf import dump_config

log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--sim", action="store_true", help="run on the built-in simulator (default without hardware)")
    p.add_argument("--duration", type=bounded(float, 0.0, 86400.0, lo_open=True, unit="s"), default=None, metavar="S",
                   help="session length (s, default 20; with --world-from the recorded run's)")
    p.add_argument("--no-motion", action="store_true", help="track without commanding the arm")
    p.add_argument("--collect", action="store_true", help="collect the target once the hold is steady")
    p.add_argument("--lockstep", action="store_true", help="simulation on its own clock (deterministic)")
    p.add_argument("--rig", metavar="RIG.toml", help="hardware: calibrated rig with [hand_eye]")
    p.add_argument("--photo", metavar="PHOTO", help="hardware: the photo of the creature to find")
    p.add_argument("--port", metavar="PORT",
                   help="hardware: the bridge's serial port or pyserial URL (`photoservo find-port`)")
    p.add_argument("--cameras", nargs=2, metavar=("LEFT", "RIGHT"),
                   help="hardware: the two OpenCV devices, index or path (`photoservo find-cameras`); "
                        "sets [cameras] kind = \"devices\", left, right")
    rec = p.add_mutually_exclusive_group()
    rec.add_argument("--record", metavar="OUT.rrd", help="recording path (default logs/<UTC time>_track.rrd)")
    rec.add_argument("--no-record", action="store_true", help="do not record")
    view = p.add_mutually_exclusive_group()
    view.add_argument("--view", action="store_true", help="spawn the Rerun viewer while recording")
    view.add_argument("--connect", metavar="URL", help="stream to a running Rerun viewer as well")
    p.add_argument("--rt-priority", type=rt_priority, metavar="N",
                   help="run the control loop with SCHED_FIFO priority N (1..99; needs the permission)")
    p.add_argument("--seed", type=seed, default=None,
                   help="tracker seed (0..2^32-1; default 0; with --world-from the recorded one)")
    p.add_argument("--world-from", metavar="REC.rrd",
                   help="simulation: the world, config and seeds of a simulated recording, closed loop with "
                        "the --config/--set changes; prints the comparison with the recorded run")
    p.add_argument("--allow-partial", action="store_true",
                   help="with --world-from: use a truncated recording (its writer was killed) as far as it goes")
    p.add_argument("--json", action="store_true", help="print the session summary as JSON on stdout")
    add_config_options(p)


def _num(v, fmt: str, unit: str = "") -> str:
    """A number for the status line, '-' when there is none yet (never 'nan')."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v:{fmt}}{unit}"


class _StatusLine:
    """Live status on stderr: one rewritten line on a terminal, a line per second otherwise,
    nothing under -q. Names the phase (servo, descend, grasp, ascend, done; "watching" under
    --no-motion) and remembers what the report needs (the last phase, whether a descent began)."""

    def __init__(self, no_motion: bool = False) -> None:
        self.tty = sys.stderr.isatty()
        self.show = logging.getLogger().isEnabledFor(logging.INFO)
        self.no_motion = no_motion
        self.last = -1.0
        self.phase = ""
        self.descended = False
        self.drawn = False

    def __call__(self, d) -> None:
        """Show a `servo.session.Status`."""
        self.phase = d.phase
        self.descended |= d.phase in ("descend", "grasp", "ascend")
        if not self.show or (not self.tty and d.t - self.last < 1.0):
            return
        self.last = d.t
        pos = d.position_mm
        pos_s = "-" if pos is None else "(" + ", ".join(f"{x:.0f}" for x in pos) + ") mm"
        rate = _num(d.fps, "4.1f", " fps") if d.fps is not None else "lockstep"  # simulated clock: no wall rate
        phase = "watching" if self.no_motion else d.phase
        line = (f"t {d.t:5.1f} s | {rate} | {d.status:<9} fit {_num(d.fitness, '.2f')} | "
                f"pos {pos_s} | alpha {_num(d.alpha, '.2f')} | "
                f"err {_num(d.error_mm, '.0f', ' mm')} {_num(d.yaw_deg, '.1f', ' deg')} | {phase}"
                + (f" | truth {_num(d.truth_error_mm, '.0f', ' mm')}" if d.truth_error_mm is not None else "")
                + (f" | stop: {d.stop}" if d.stop and not self.no_motion else "")
                + (f" | {d.link.text()}" if d.link else ""))
        self.drawn = True
        if self.tty:
            print("\r" + line[:160].ljust(160), end="", file=sys.stderr, flush=True)
        else:
            print(line, file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.tty and self.drawn:
            print(file=sys.stderr)
            self.drawn = False


def run(args: argparse.Namespace) -> int:
    if args.view:
        check_display("--view")
    if args.world_from:
        return _run_world_from(args)
    if args.allow_partial:
        raise InputError("--allow-partial: only with --world-from")
    args.duration = 20.0 if args.duration is None else args.duration
    args.seed = 0 if args.seed is None else args.seed
    cfg = load_config(args.config, args.overrides)
    if args.cameras:
        cams = dataclasses.replace(cfg.cameras, kind="devices", left=args.cameras[0], right=args.cameras[1])
        cams.validate("cameras")
        cfg = dataclasses.replace(cfg, cameras=cams)
    hardware = bool(args.port) or cfg.cameras.kind != "none"
    if hardware and args.sim:
        raise InputError("--sim cannot be combined with --port or a configured [cameras] source")
    if hardware:
        return _run_hardware(args, cfg)
    return _run_sim(args, cfg)


def _run_world_from(args: argparse.Namespace) -> int:
    """`track --sim --world-from REC`: the recorded world (its [sim], seeds and length) with the new
    config, closed loop, then the comparison table against the recorded run. The run is recorded
    as usual (to a temporary file with --no-record, for the table)."""
    import tempfile

    from photoservo.record.files import default_path
    from photoservo.record.replay import compare_runs, world_from

    if args.port or args.cameras:
        raise InputError("--world-from runs the simulator: it cannot be combined with --port or --cameras")
    w = world_from(args.world_from, args.config, args.overrides, args.seed, args.allow_partial)
    if w.cfg.cameras.kind != "none":
        raise InputError("--world-from runs the simulator: config key 'cameras.kind' must be \"none\"")
    if args.duration is None:
        args.duration = w.duration_s
    args.seed = w.seed
    log.info(f"world from {w.path}: [sim] seed {w.cfg.sim.seed}, tracker seed {w.seed}, {args.duration:.2f} s"
             + (f"; [sim] changed by you: {', '.join(w.changed_sim_keys)}" if w.changed_sim_keys else ""))
    tmp = None
    if args.no_record:
        tmp = tempfile.TemporaryDirectory(prefix="photoservo-world-from-")
        args.no_record, args.record = False, str(Path(tmp.name) / "run.rrd")
        args.temporary_record = True  # for the table only: deleted afterwards, so not reported
    elif args.record is None:
        args.record = str(default_path("track", w.cfg.recording.dir))
    try:
        code = _run_sim(args, w.cfg)
        print(compare_runs(w.recording, args.record, "recorded", "this run"), file=sys.stderr if args.json else sys.stdout)
    finally:
        if tmp is not None:
            tmp.cleanup()
    return code


def _recorder(args, cfg):
    if args.no_record:
        return None
    from photoservo.record.recorder import Recorder

    return Recorder.from_config(cfg.recording, "track", args.record, view=args.view, connect_url=args.connect)


def _setup_static(rec, cfg, rig, photo, model, seed: int, extra: dict) -> None:
    from photoservo.vision.rig import dump_rig

    rec.log_static_setup(dump_rig(rig), photo, model, dump_config(cfg), {"tracker": seed, **extra},
                         {"photoservo": __version__})


def _collection(s: dict, cfg, status: _StatusLine) -> str:
    """Whether the creature was collected, and if not, why (the report's one line)."""
    if s["collected"]:
        return "collected"
    if s["faults"]:
        return "not completed: a fault stopped the session (below)"
    if status.descended:
        return "not completed: the descent was aborted (target lost) and the arm climbed back"
    sv = cfg.servo
    return (f"not completed: the hold never stayed within {sv.hold_tolerance_mm:g} mm and "
            f"{sv.hold_tolerance_deg:g} deg for {sv.hold_time_s:g} s before the session ended "
            f"(last phase: {status.phase or 'none'}; a longer --duration, or [servo] hold_* keys)")


def _report(args, sc, rec, cfg, status, bridge: dict | None = None) -> int:
    s = sc.summary()
    if bridge:  # the simulator's emulated bridge: setpoints taken, refused (by reason), watchdog stops
        s["bridge"] = bridge
    if getattr(args, "temporary_record", False):
        rec = None
    if rec is not None and rec.written:
        s["recording"] = _recording_files(rec)
    s["load_average"] = round(os.getloadavg()[0], 2)  # the 1-minute load at the end: what the run competed with
    if args.json:
        print(dumps_strict(s))
    else:
        t = s["timings_ms_median"]
        print(f"frames {s['frames']}, found {100 * s['found_ratio']:.0f} %, lost {s['lost_events']}, "
              f"acquisitions {s['acquisitions']}")
        if (note := _busy_note(s, os.cpu_count() or 1, cfg.servo.max_estimate_age_cap_s)) is not None:
            print(note)
        if args.collect:
            print(f"collection: {_collection(s, cfg, status)}")
        if not math.isnan(s["hold_error_rms_mm"]):
            print(f"hold error vs truth (after settling): {s['hold_error_rms_mm']:.1f} mm RMS, "
                  f"{s['hold_yaw_error_rms_deg']:.2f} deg RMS yaw")
        if "track_error_mm" in s:
            e = s["track_error_mm"]
            print(f"track error vs truth (fully in view): median {_num(e['median'], '.1f')}, p95 "
                  f"{_num(e['p95'], '.1f')} mm; false tracks {s['false_tracks']}; re-acquisitions "
                  f"[{', '.join(_num(x, '.2f') for x in s['reacquisition_s'])}] s")
        if bridge:
            print(f"emulated bridge: {bridge.get('watchdog_stops', 0)} watchdog stops, "
                  f"{bridge.get('refused', 0)} setpoints refused of {bridge.get('refused', 0) + bridge.get('accepted', 0)}")
        print("median ms: " + ", ".join(f"{k} {v:.1f}" for k, v in t.items()))
        for f in s["faults"]:
            print(f"fault: {f}")
        if rec is not None and rec.written:
            print(f"recording: {_recording_files(rec)}")
    return EXIT_HARDWARE if s["faults"] else 0


def _busy_note(s: dict, cpus: int, late_s: float) -> str | None:
    """The summary's line for a session that found the creature in under half its frames on a
    busy machine (1-minute load average above the CPU count) and whose first track came later
    than `late_s` (the servo's estimate age cap, s) or never: when it came, and why that can lose
    a drifting creature. None otherwise (a prompt first track followed by a creature drifting out
    of a still arm's view, `--no-motion`, is not the machine's doing)."""
    if s["found_ratio"] >= 0.5 or s["load_average"] <= cpus:
        return None
    if s.get("first_track_s") is not None and s["first_track_s"] <= late_s:
        return None
    first = "never came" if s.get("first_track_s") is None else f"came {s['first_track_s']:.1f} s into the session"
    return (f"note: the machine was busy (load average {s['load_average']:.1f} on {cpus} CPUs) and the first "
            f"track {first}: the first whole-volume search then takes seconds, and a drifting creature "
            "can leave the still arm's view before it ends (README: Tracking, on a busy machine). "
            "Close other programs and run again.")


def _recording_files(rec) -> str | None:
    """The one file written (what `rerun`, `rerun rrd stats` and `photoservo replay` open), or
    None when nothing was recorded (the session never produced a frame or arm sample)."""
    return str(rec.path) if rec.written else None


def _say(line: str) -> None:
    """A one-line notice on stderr before the session starts (the warm start's on a first run)."""
    print(line, file=sys.stderr, flush=True)


def _run_sim(args, cfg) -> int:
    from photoservo.sim.emulator_process import EmulatorProcess
    from photoservo.sim.run import build_sim, run_lockstep, run_sim_realtime, sim_config

    cfg = sim_config(cfg)  # the recorded config says what the tracker knew: the water plane
    if args.lockstep:  # the recorded effective config then says how the run was clocked (replay reads it)
        cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, lockstep=True))
    sim = build_sim(cfg)
    status = _StatusLine(args.no_motion)

    def session(held: dict):
        rec = held["rec"] = _recorder(args, cfg)
        if rec is not None:
            _setup_static(rec, cfg, sim.rig, sim.scene.photo, sim.scene.model, args.seed, {"sim": cfg.sim.seed})
        if args.lockstep or cfg.sim.lockstep:
            return run_lockstep(cfg, args.duration, collect=args.collect, no_motion=args.no_motion,
                                recorder=rec, status=status, seed=args.seed, setup=sim, say=_say)
        emu = EmulatorProcess(cfg.emulator, sim.limits, q0=sim.q0)  # its own process, prioritised
        emu.start()
        try:
            return run_sim_realtime(cfg, args.duration, sim, emu, collect=args.collect, no_motion=args.no_motion,
                                    recorder=rec, status=status, seed=args.seed, rt_priority=args.rt_priority,
                                    say=_say)
        finally:
            emu.stop()
            m = emu.summary  # what the bridge did with the setpoints, for the summary
            held["bridge"] = {k: m[k] for k in ("accepted", "refused", "refusals", "watchdog_stops") if k in m}
            if rec is not None:  # what the emulated bridge saw: the stop and servo off, in order
                rec.event(rec.last_t, f"emulated bridge: {emu.summary.get('end', 'no report')}")
    return _finish(args, cfg, status, session)


def _finish(args, cfg, status: _StatusLine, session) -> int:
    """Run `session(held)` — which puts its recorder (or None) in held["rec"] as soon as it has
    made it and returns the scores — then end the status line, close the recording and report:
    the summary, or after Ctrl-C / SIGTERM / SIGHUP (the session stopped the arm in order) the
    one line of `report_stop`."""
    held: dict = {}
    stop: KeyboardInterrupt | None = None
    try:
        sc = session(held)
        if held.get("rec") is not None:  # what ended the session, where the event log shows it
            for f in sc.faults:
                held["rec"].event(held["rec"].last_t, f"fault: {f}", level="ERROR")
    except KeyboardInterrupt as e:
        stop = e
    finally:
        status.close()
        if held.get("rec") is not None:
            held["rec"].close()
    rec = held.get("rec")
    if stop is not None:
        return report_stop("track", stop, _stopped(args, rec))
    return _report(args, sc, rec, cfg, status, held.get("bridge"))


def _stopped(args, rec) -> str:
    """What an interrupted session did, for its one line."""
    what = "tracking stopped" if args.no_motion else "controlled stop, servo off"
    return what + (f"; recording: {_recording_files(rec)}" if rec is not None and rec.written else "")


def _run_hardware(args, cfg) -> int:
    from photoservo.fileio import read_image
    from photoservo.servo.realtime import run_realtime
    from photoservo.vision.photo_model import build_photo_model
    from photoservo.vision.rig import load_rig
    from photoservo.vision.frame_reader import LatestFrameReader
    from photoservo.vision.source_config import source_config
    from photoservo.vision.sources import make_source

    for flag in ("rig", "photo", "port"):
        if not getattr(args, flag):
            raise InputError(f"hardware tracking needs --{flag} (or use --sim)")
    rig = load_rig(args.rig)
    if rig.hand_eye is None:
        raise InputError(f"{args.rig}: no [hand_eye] table: run `photoservo calibrate hand-eye` before servoing")
    photo = read_image(args.photo, "photo")
    model = build_photo_model(photo, cfg.photo_model)
    src_cfg = source_config(cfg.cameras)
    if src_cfg is None:
        raise InputError("config key 'cameras.kind' is \"none\": configure the stereo cameras")
    if "://" not in args.port and not Path(args.port).exists():
        raise InputError(f"--port {args.port}: cannot open: no such device; `photoservo find-port` lists the serial ports")
    status = _StatusLine(args.no_motion)

    def session(held: dict):
        with LatestFrameReader(make_source(src_cfg)) as reader:  # cameras first: a failed start leaves no recording
            rec = held["rec"] = _recorder(args, cfg)
            if rec is not None:
                _setup_static(rec, cfg, rig, photo, model, args.seed, {})
            return run_realtime(cfg, args.duration, port=args.port, read_frame=lambda: reader.latest(timeout_s=0.5),
                                model=model, rig=rig, collect=args.collect, no_motion=args.no_motion, recorder=rec,
                                status=status, seed=args.seed, rt_priority=args.rt_priority, say=_say)
    return _finish(args, cfg, status, session)
