"""photoservo pa10-sim [--link PATH] [--baud N] [--rate HZ] [--drop P] [--corrupt P]
                      [--delay P] [--delay-ms MS] [--seed N] [--config CFG.toml] [--set ...]

The PA-10 serial-bridge emulator (photoservo/sim/emulator.py) on a pseudo-terminal: prints the
device path on stdout (one line), optionally symlinks it at --link, and speaks the bridge
protocol (docs/protocol.md) until Ctrl-C, SIGTERM or SIGHUP (exit 130, 143, 129), then prints
what it received (SERVO_ON / STOP / SERVO_OFF counts, setpoints, watchdog stops, line errors).
Defaults from the [emulator] config section.

Examples (two shells):
    photoservo pa10-sim --link /tmp/pa10
    photoservo move --port /tmp/pa10 --joints 10 30 0 60 0 90 0
    photoservo pa10-sim --corrupt 0.001 --drop 0.001 --seed 1   # a noisy line
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time

from photoservo.cli.options import add_config_options, bounded, realtime_or_input_error, rt_priority, seed
from photoservo.cli.signals import exit_code
from photoservo.config import load_config
from photoservo.errors import HardwareError
from photoservo.sim.emulator import Emulator

# CLI flag -> [emulator] key
FLAGS = {"baud": "baud", "rate": "control_hz", "drop": "drop", "corrupt": "corrupt",
         "delay": "delay", "delay_ms": "delay_ms", "seed": "seed", "brake_after": "brake_after_s"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    prob = bounded(float, 0.0, 1.0)
    p.add_argument("--link", metavar="PATH", help="also make a symlink PATH -> the pty (removed on exit)")
    p.add_argument("--baud", type=bounded(int, 0, 10_000_000), help="pace bytes as an 8N1 line at this rate; 0 = unpaced (default 921600)")
    p.add_argument("--rate", type=bounded(float, 1.0, 10_000.0, unit="Hz"),
                   help="control rate (Hz, default 250); state is sent at the same rate")
    p.add_argument("--drop", type=prob, metavar="P", help="probability that a byte is dropped (each direction, 0..1)")
    p.add_argument("--corrupt", type=prob, metavar="P", help="probability that a byte is corrupted (0..1)")
    p.add_argument("--delay", type=prob, metavar="P", help="probability that a byte stalls the line by --delay-ms (0..1)")
    p.add_argument("--delay-ms", type=bounded(float, 0.0, 10_000.0, unit="ms"), metavar="MS",
                   help="length of one injected stall (ms, default 20)")
    p.add_argument("--brake-after", type=bounded(float, 0.0, 3600.0, unit="s"), metavar="S",
                   help="setpoint silence before the brakes engage (s)")
    p.add_argument("--seed", type=seed, help="seed of the fault injection (0..2^32-1)")
    p.add_argument("--rt-priority", type=rt_priority, metavar="N",
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
    path = emu.start()
    code = 0
    try:
        print(path, flush=True)
        where = f" (and {args.link})" if args.link else ""
        faults = ", ".join(f"{k} {getattr(params, k)}" for k in ("drop", "corrupt", "delay") if getattr(params, k))
        print(f"pa10-sim: bridge on {path}{where}, {params.control_hz:g} Hz, "
              f"{'unpaced' if params.baud == 0 else f'{params.baud} baud'}"
              f"{', faults: ' + faults if faults else ''}; Ctrl-C to stop", file=sys.stderr, flush=True)
        while emu.error is None:
            time.sleep(0.2)
        raise HardwareError(f"emulator stopped: {emu.error}")
    except KeyboardInterrupt as e:  # Ctrl-C, SIGTERM, SIGHUP (cli/signals.py): the normal way to end it
        code = exit_code(e)
    finally:
        emu.stop()
    d, m = emu.decoder, emu.model
    print(f"pa10-sim: stopped; {m.describe_end()}; setpoints accepted {m.accepted}, refused {m.refused}; "
          f"frames dropped (CRC/COBS/length) {d.errors}, resyncs {d.resyncs}; states sent {emu.states_sent}, "
          f"skipped (line busy) {emu.states_skipped}", file=sys.stderr)
    return code
