"""`photoservo` — one verb per module (`photoservo/cli/<verb>.py`), each with
`add_arguments(parser)` and `run(args) -> int`. Only the chosen verb's module is imported.

Bad input (an InputError) prints one line naming the problem and exits with status 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from photoservo import __version__
from photoservo.errors import InputError

# verb -> (module, one-line help). Add a verb here when its module lands.
VERBS: dict[str, tuple[str, str]] = {
    "config": ("photoservo.cli.config", "print the effective configuration"),
    "calibrate": ("photoservo.cli.calibrate", "calibrate the stereo rig, hand-eye transform and water plane"),
    "model": ("photoservo.cli.model", "build the photo-model of a photo and preview its sampling points"),
    "synth": ("photoservo.cli.synth", "render a synthetic stereo scene with ground truth"),
    "scan": ("photoservo.cli.scan", "fitness maps (pose axis x alpha) around a given pose, as heatmap PNGs"),
    "estimate": ("photoservo.cli.estimate", "find the photo's creature in a stereo pair: 6-DOF pose and size"),
    "pa10-sim": ("photoservo.cli.pa10_sim", "PA-10 serial-bridge emulator on a pty (prints the device path)"),
    "move": ("photoservo.cli.move", "move the arm to joint angles (deg) or home through the bridge, jerk-limited"),
    "track": ("photoservo.cli.track", "track a floating creature and servo the arm over it (main job)"),
    "replay": ("photoservo.cli.replay", "re-run a recording's tracker and control law with a changed config; compare"),
    "tune": ("photoservo.cli.tune", "tune config keys automatically: an Optuna study on simulated worlds and recordings"),
}


def build_parser(verb: str | None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="photoservo",
        description="Find, track and collect a floating creature from one photo (stereo photo-model + PA-10).",
    )
    parser.add_argument("--version", action="version", version=f"photoservo {__version__}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    for name, (module, help_) in VERBS.items():
        p = sub.add_parser(name, help=help_, description=help_)
        if name == verb:
            importlib.import_module(module).add_arguments(p)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    verb = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(verb if verb in VERBS else None)
    args = parser.parse_args(argv)
    if args.verb is None:
        parser.print_help()
        return 2
    try:
        return int(importlib.import_module(VERBS[args.verb][0]).run(args) or 0)
    except InputError as e:
        print(f"photoservo {args.verb}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"photoservo {args.verb}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
