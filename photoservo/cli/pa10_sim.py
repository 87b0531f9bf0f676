"""photoservo pa10-sim [--link PATH] [--baud N] [--rate HZ] [--drop P] [--corrupt P]
                      [--delay P] [--delay-ms MS] [--seed N] [--config CFG.toml] [--set ...]

The PA-10 serial-bridge emulator (photoservo/sim/emulator.py) on a pseudo-terminal: prints the
device path on stdout (one line), optionally symlinks it at --link, and speaks the bridge
protocol (docs/protocol.md) until Ctrl-C or SIGTERM. Defaults from the [emulator] config section.

Example (two shells):
    photoservo pa10-sim --link /tmp/pa10
    photoservo move --port /tmp/pa10 --joints 10 30 0 60 0 90 0
"""

from __future__ import annotations

import argparse
import dataclasses
import signal
import sys
import threading

from photoservo.errors import InputError
from photoservo.robot.clock import set_realtime
from photoservo.sim.emulator import Emulator
from photoservo.cli.config import add_config_options
from photoservo.config import load_config

# CLI flag -> [emulator] key
FLAGS = {"baud": "baud", "rate": "control_hz", "drop": "drop", "corrupt": "corrupt",
         "delay": "delay", "delay_ms": "delay_ms", "seed": "seed", "brake_after": "brake_after_s"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--link", metavar="PATH", help="also make a symlink PATH -> the pty (removed on exit)")
    p.add_argument("--baud", type=int, help="pace bytes as an 8N1 line at this rate; 0 = unpaced (default 921600)")
    p.add_argument("--rate", type=float, help="control rate (Hz, default 250); state is sent at the same rate")
    p.add_argument("--drop", type=float, metavar="P", help="probability that a byte is dropped (each direction)")
    p.add_argument("--corrupt", type=float, metavar="P", help="probability that a byte is corrupted")
    p.add_argument("--delay", type=float, metavar="P", help="probability that a byte stalls the line by --delay-ms")
    p.add_argument("--delay-ms", type=float, metavar="MS", help="length of one injected stall (ms, default 20)")
    p.add_argument("--brake-after", type=float, metavar="S", help="setpoint silence before the brakes engage (s)")
    p.add_argument("--seed", type=int, help="seed of the fault injection")
    p.add_argument("--rt-priority", type=int, metavar="N",
                   help="run with SCHED_FIFO real-time priority N (1..99; Linux, needs permission), as a "
                        "stand-in for the bridge's dedicated hardware")
    add_config_options(p)


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config, args.overrides)
    changes = {key: getattr(args, flag) for flag, key in FLAGS.items() if getattr(args, flag) is not None}
    if args.rate is not None and "state_hz" not in changes:
        changes["state_hz"] = min(cfg.emulator.state_hz, args.rate)
    params = dataclasses.replace(cfg.emulator, **changes)
    params.validate("emulator")  # the flags go through the config's checks (InputError, exit 2)
    if args.rt_priority is not None:  # before the emulator thread starts: it inherits the policy
        realtime_or_input_error(args.rt_priority)
    emu = Emulator(params, link=args.link)
    done = threading.Event()

    def on_signal(signum, frame):  # SIGTERM (and SIGINT) end the emulator cleanly
        done.set()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    path = emu.start()
    try:
        print(path, flush=True)
        where = f" (and {args.link})" if args.link else ""
        faults = ", ".join(f"{k} {getattr(params, k)}" for k in ("drop", "corrupt", "delay") if getattr(params, k))
        print(f"pa10-sim: bridge on {path}{where}, {params.control_hz:g} Hz, "
              f"{'unpaced' if params.baud == 0 else f'{params.baud} baud'}"
              f"{', faults: ' + faults if faults else ''}; Ctrl-C to stop", file=sys.stderr, flush=True)
        while not done.wait(0.2):
            if emu.error is not None:
                print(f"pa10-sim: error: emulator stopped: {emu.error}", file=sys.stderr)
                return 1
    finally:
        emu.stop()
        for s, h in old.items():
            signal.signal(s, h)
    d, m = emu.decoder, emu.model
    print(f"pa10-sim: stopped; setpoints accepted {m.accepted}, refused {m.refused}; watchdog stops "
          f"{m.watchdog_stops}; frames dropped "
          f"(CRC/COBS/length) {d.errors}, resyncs {d.resyncs}; states sent {emu.states_sent}, "
          f"skipped (line busy) {emu.states_skipped}", file=sys.stderr)
    return 0


def realtime_or_input_error(priority: int) -> None:
    """`--rt-priority N`: SCHED_FIFO for this process, or a one-line InputError."""
    try:
        set_realtime(priority)
    except ValueError as e:
        raise InputError(f"--rt-priority {priority}: {e}") from None
    except (OSError, AttributeError) as e:
        raise InputError(f"--rt-priority {priority}: not permitted here ({e}); run without it, "
                         "or grant CAP_SYS_NICE / an rtprio limit") from None
