"""`photoservo` — one verb per module (`photoservo/cli/<verb>.py`), each with
`add_arguments(parser)` and `run(args) -> int`. Only the chosen verb's module is imported.

Exit status (every verb; README "Exit status"):
    0    ok / found
    1    not found (estimate: no creature; find-cameras, find-port: nothing found)
    2    bad input: one line naming the file, key, flag or value; nothing half-written
    3    hardware or link failure (a bridge gone silent, a camera that stopped); the arm is stopped
    128+N  ended by signal N after a controlled stop: 130 Ctrl-C, 143 SIGTERM, 129 SIGHUP
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from photoservo import __version__
from photoservo.cli.log import add_verbosity_options, setup_logging
from photoservo.cli.signals import exit_code, signal_name, stop_on_signals
from photoservo.errors import EXIT_BAD_INPUT, EXIT_HARDWARE, HardwareError, InputError

log = logging.getLogger("photoservo.cli")

# verb -> (module, one-line help). Add a verb here when its module lands.
VERBS: dict[str, tuple[str, str]] = {
    "track": ("photoservo.cli.track", "track a floating creature and servo the arm over it (main job)"),
    "estimate": ("photoservo.cli.estimate", "find the photo's creature in a stereo pair: 6-DOF pose and size"),
    "model": ("photoservo.cli.model", "build the photo-model of a photo and preview its sampling points"),
    "synth": ("photoservo.cli.synth", "render a synthetic stereo scene with ground truth"),
    "scan": ("photoservo.cli.scan", "fitness maps (pose axis x alpha) around a given pose, as heatmap PNGs"),
    "calibrate": ("photoservo.cli.calibrate", "calibrate the stereo rig, hand-eye transform and water plane"),
    "replay": ("photoservo.cli.replay", "re-run a recording's tracker and control law with a changed config; compare"),
    "move": ("photoservo.cli.move", "move the arm to joint angles (deg) or home through the bridge, jerk-limited"),
    "pa10-sim": ("photoservo.cli.pa10_sim", "PA-10 serial-bridge emulator on a pty (prints the device path)"),
    "tune": ("photoservo.cli.tune", "tune config keys automatically: an Optuna study on simulated worlds and recordings"),
    "find-cameras": ("photoservo.cli.find_cameras", "list the cameras and video sources OpenCV can open, one snapshot each"),
    "find-port": ("photoservo.cli.find_port", "list serial ports and find the one the arm's bridge answers on"),
    "config": ("photoservo.cli.config", "print the effective configuration"),
}

EPILOG = """exit status: 0 ok/found, 1 not found, 2 bad input, 3 hardware or link failure,
128+N stopped by signal N (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP).
Run `photoservo VERB --help` for a verb's options and examples."""


class Parser(argparse.ArgumentParser):
    """argparse with a one-line error (no usage block): `photoservo VERB: error: ... (see --help)`,
    exit status 2, like every other bad input."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser(verb: str | None) -> argparse.ArgumentParser:
    parser = Parser(
        prog="photoservo",
        description="Find, track and collect a floating creature from one photo (stereo photo-model + PA-10).",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"photoservo {__version__}")
    add_verbosity_options(parser)
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    for name, (module, help_) in VERBS.items():
        if name != verb:
            sub.add_parser(name, help=help_, description=help_)
            continue
        mod = importlib.import_module(module)
        p = sub.add_parser(name, help=help_, description=mod.__doc__, epilog=EPILOG,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        mod.add_arguments(p)
        add_verbosity_options(p, argparse.SUPPRESS)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    verb = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(verb if verb in VERBS else None)
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # --help, --version (0) or a bad argument (2, one line already printed)
        return int(e.code or 0)
    if args.verb is None:
        parser.print_help(sys.stderr)
        return EXIT_BAD_INPUT
    restore = setup_logging(args.verbose - args.quiet)
    try:
        with stop_on_signals():
            return _run(args)
    except KeyboardInterrupt as e:  # a verb without its own stop handling, or between steps
        print(f"photoservo {args.verb}: interrupted by {signal_name(e)}", file=sys.stderr)
        return exit_code(e)
    finally:
        restore()


def _run(args: argparse.Namespace) -> int:
    """The verb's run(); bad input and hardware failures become one line and their exit status."""
    try:
        return int(importlib.import_module(VERBS[args.verb][0]).run(args) or 0)
    except InputError as e:
        print(f"photoservo {args.verb}: error: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except HardwareError as e:
        print(f"photoservo {args.verb}: error: {e}", file=sys.stderr)
        return EXIT_HARDWARE


if __name__ == "__main__":
    sys.exit(main())
