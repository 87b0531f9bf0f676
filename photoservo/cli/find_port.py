"""photoservo find-port [PORT ...] [--no-probe] [--json] [--config CFG.toml] [--set ...]

Lists the serial ports pyserial sees (and any PORT given: a pty path such as the one
`photoservo pa10-sim` prints, or a pyserial URL) and asks each for the arm's bridge: a HELLO
frame at the [link] baud, answered by VERSION (docs/protocol.md). The port to give `move`,
`track` and `calibrate --port` is the one marked BRIDGE. --no-probe lists without writing to any
port (asking writes a few bytes to each: leave it off for ports holding other devices).

Exit status: 0 a bridge answered, 1 none did, 2 bad input.

Examples:
    photoservo find-port
    photoservo find-port /tmp/pa10 socket://192.168.0.20:4000
    photoservo find-port --no-probe --json
"""

from __future__ import annotations

import argparse
import logging

from photoservo.cli.options import add_config_options
from photoservo.cli.output import print_json
from photoservo.config import load_config
from photoservo.errors import EXIT_NOT_FOUND, EXIT_OK

log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("ports", nargs="*", metavar="PORT",
                   help="also ask these (a pty path, a symlink such as pa10-sim --link, a pyserial URL)")
    p.add_argument("--no-probe", action="store_true", help="list the ports only; write nothing to them")
    p.add_argument("--json", action="store_true", help="print the list as JSON on stdout")
    add_config_options(p)


def run(args: argparse.Namespace) -> int:
    from photoservo.robot.ports import find_ports

    cfg = load_config(args.config, args.overrides)
    ports = find_ports(cfg.link, tuple(args.ports), probe=not args.no_probe)
    bridges = [p for p in ports if p.bridge]
    if args.json:
        print_json([{"device": p.device, "description": p.description, "hwid": p.hwid, "bridge": p.bridge,
                     "why": p.why or None} for p in ports])
    else:
        for p in ports:
            print(p.describe())
        if not ports:
            print("no serial ports (pyserial lists none; a pa10-sim pty must be given as PORT)")
    if not args.no_probe:
        log.info(f"{len(bridges)} of {len(ports)} ports answered as the bridge"
                 + (f": use --port {bridges[0].device}" if bridges else ""))
    return EXIT_OK if bridges or args.no_probe else EXIT_NOT_FOUND
