"""photoservo replay REC.rrd [--config CFG.toml] [--set key=value ...] [--out NEW.rrd | --no-record]
                        [--view] [--fixed-generations] [--allow-partial] [--json]

Re-runs a recorded session from its file alone (record/replay.py): the recorded frames through
the tracker with the recorded seed (deterministic: no time budget), the control law open loop on
the recorded joint states, with the recorded config changed by --config/--set; writes a new,
complete recording (default logs/<UTC time>_replay.rrd; none with --no-record) and prints the
two runs side by side. A truncated recording (its writer was killed) is refused with what is
missing and how much was read, unless --allow-partial.

Servo gains change only the commands here (the arm is not moved); to see their effect on the
run, re-run the same simulated world closed loop: `photoservo track --sim --world-from REC`.

Progress is drawn on a terminal only; -q hides it and the header line.

Examples:
    photoservo replay logs/20261122T052106Z_track.rrd --set ga.population=60
    photoservo replay run.rrd --set tracker.generations_per_frame=4 --out run_g4.rrd --view
    photoservo replay killed.rrd --allow-partial --no-record
"""

from __future__ import annotations

import argparse
import logging

from photoservo.cli.options import add_config_options, check_display
from photoservo.cli.output import print_json
from photoservo.cli.output import progress as progress_bar

log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", metavar="REC.rrd", help="a compact or full recording (not preview)")
    out = p.add_mutually_exclusive_group()
    out.add_argument("--out", metavar="NEW.rrd", help="the replay's recording (default logs/<UTC time>_replay.rrd)")
    out.add_argument("--no-record", action="store_true", help="do not keep a recording of the replay")
    p.add_argument("--allow-partial", action="store_true",
                   help="replay a truncated recording (no footer: its writer was killed) as far as it goes")
    p.add_argument("--view", action="store_true", help="spawn the Rerun viewer while writing the replay")
    p.add_argument("--fixed-generations", action="store_true",
                   help="run [tracker] generations_per_frame on every tracking frame, even for a real-time "
                        "recording (default there: each frame's recorded count)")
    p.add_argument("--json", action="store_true", help="print the comparison as JSON on stdout")
    add_config_options(p)


def run(args: argparse.Namespace) -> int:
    from photoservo.record.replay import load_replay, replay

    if args.view:
        check_display("--view")
    setup = load_replay(args.recording, args.config, args.overrides, args.fixed_generations, args.allow_partial)
    n = len(setup.recording.frames)
    log.info(f"replaying {n} frames of {args.recording} (tracker seed {setup.seed}; {setup.generations_note})")
    with progress_bar(n, "replay", unit="frame") as bar:
        res = replay(setup, args.out, view=args.view, progress=lambda k, total: bar.update(k - bar.n),
                     record=not args.no_record)
    out = None if res.out_path is None else str(res.out_path)
    if args.json:
        rows = {r.key: {"recorded": r.a, "replay": r.b} for r in res.comparison.rows}
        print_json({"recording": str(setup.path), "replay": out,
                    "frames": len(res.frames), "seconds": res.seconds, "fps": res.fps,
                    "generations": setup.generations_note, "table": rows})
    else:
        print(res.comparison)
        print(f"replayed {len(res.frames)} frames in {res.seconds:.1f} s ({res.fps:.2f} frames/s); "
              f"recording: {out or 'none (--no-record)'}")
    return 0
