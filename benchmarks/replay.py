"""Replay speed (issue 6 item 7): stereo frames per second of `photoservo replay`.

Makes one lockstep recording of the simulator (`track --sim --lockstep`, 640x480 stereo, the
default [recording] mode) and replays it `--repeats` times per config change, reporting (median of the runs):

  load s         `load_replay`: reading the recording's setup and per-frame data (no images)
  replay fps     recorded frames / time of `replay()`'s loop: frames streamed from the file,
                 hue + tracker (no time budget), the open-loop control law at the control
                 rate, and the new recording written
  end-to-end fps frames / (load + replay + reading the new recording back for the table)
  tracker ms     mean hue + GA time per frame (the table's 'tracker ms per frame' row)
  other ms       the rest of the loop per frame: reading/decoding the frames, the open-loop
                 control law (~12 periods per frame at 250 Hz and 15 fps), writing the recording
  identical      the replay's estimates equal the recorded run's (same config only)

Prints a table and writes benchmarks/out/replay.json.
Run: python benchmarks/replay.py [--duration 2] [--fps 15] [--repeats 3]
The machine is shared by several engineers: times are indicative, not a clean measurement.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

from photoservo.fileio import write_text_atomic
from photoservo.cli.main import main as cli
from photoservo.record.replay import load_replay, replay
from photoservo.record.reader import read_recording

CHANGES: dict[str, list[str]] = {
    "same config": [],
    "generations_per_frame=4": ["tracker.generations_per_frame=4"],
    "ga.population=60": ["ga.population=60"],
}


def _key(e) -> tuple:
    return (e.frame, e.found, e.fitness, None if e.position_mm is None else tuple(e.position_mm))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=2.0, help="recorded session length (s)")
    ap.add_argument("--fps", type=float, default=15.0, help="simulated camera rate (Hz)")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-replay-") as tmp:
        rec = Path(tmp) / "run.rrd"
        t0 = time.perf_counter()
        rc = cli(["track", "--sim", "--lockstep", "--duration", str(args.duration), "--set",
                  f"sim.camera_fps={args.fps}", "--record", str(rec)])
        if rc != 0:
            raise SystemExit(f"recording failed ({rc})")
        record_s = time.perf_counter() - t0
        recorded = read_recording(rec)
        ref = [_key(e) for e in recorded.estimates]
        n = len(recorded.frames)
        runs: dict[str, list[dict]] = {name: [] for name in CHANGES}
        for r in range(args.repeats):   # interleaved: the machine's load drifts between runs
            for i, (name, overrides) in enumerate(CHANGES.items()):
                t0 = time.perf_counter()
                setup = load_replay(rec, overrides=overrides)
                t1 = time.perf_counter()
                res = replay(setup, Path(tmp) / f"replay_{i}_{r}.rrd")
                t2 = time.perf_counter()
                tracker_ms = res.comparison.row("tracker_ms").b
                runs[name].append({
                    "load_s": t1 - t0, "replay_fps": n / res.seconds, "end_to_end_fps": n / (t2 - t0),
                    "tracker_ms": tracker_ms, "other_ms": 1e3 * res.seconds / n - tracker_ms,
                    "identical": [_key(e) for e in read_recording(res.out_path).estimates] == ref})
        rows = [{"change": name, "frames": n,
                 **{k: statistics.median(x[k] for x in rs) for k in ("load_s", "replay_fps", "end_to_end_fps",
                                                                       "tracker_ms", "other_ms")},
                 "identical": all(x["identical"] for x in rs)} for name, rs in runs.items()]
    head = (f"{'change':<26}{'frames':>7}{'load s':>8}{'replay fps':>12}{'end-to-end fps':>16}"
            f"{'tracker ms':>12}{'other ms':>10}  identical")
    print(f"replay of a {args.duration:g} s lockstep recording at {args.fps:g} fps, 640x480 stereo, lossless "
          f"(recorded in {record_s:.1f} s); median of {args.repeats}; machine shared and loaded")
    print(head)
    for r in rows:
        print(f"{r['change']:<26}{r['frames']:>7}{r['load_s']:>8.2f}{r['replay_fps']:>12.2f}"
              f"{r['end_to_end_fps']:>16.2f}{r['tracker_ms']:>12.1f}{r['other_ms']:>10.1f}  {r['identical']}")
    out = Path(__file__).parent / "out" / "replay.json"
    write_text_atomic(out, json.dumps({"duration_s": args.duration, "camera_fps": args.fps,
                                       "repeats": args.repeats, "record_s": record_s,
                                       "note": "machine shared by several engineers (loaded)",
                                       "rows": rows}, indent=1))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
