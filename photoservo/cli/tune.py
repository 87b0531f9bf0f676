"""photoservo tune --space KEY=LO:HI[:log] | KEY=A,B,C ... [--space-file TUNE.toml]
                  [--worlds N] [--world-from REC ...] [--recordings REC ...]
                  [--objectives hold[,track,lost,cpu]] [--weights NAME=W,...] [--trials N]
                  [--study NAME] [--storage URL] [--jobs N] [--seed N]
                  [--duration S] [--settle S] [--holdout-worlds M] [--holdout-recordings REC ...]
                  [--out BEST.toml] [--plot DIR] [--config CFG.toml] [--set key=value ...]

Tune config keys automatically (issue 14): an Optuna study over the search space, each trial the
configuration run on simulated worlds (closed loop, lockstep: servo keys and everything else)
and/or replayed recordings (open loop: tracker, GA and photo-model keys), scored with the
session's own numbers (photoservo/tune/objectives.py: hold, track, lost, cpu; lower is better).
One objective, a weighted sum (--weights), or a Pareto front (several --objectives).

The study lives in its storage (default: the SQLite file tune.db here) and continues where it
stopped when run again with the same --study; --trials is the study's total. With
`--storage postgresql://user@host/db` every node of a cluster runs the same command and the
trials spread over them. Ctrl-C or SIGTERM stops after the running trials (exit 130 / 143); the
study keeps them.

At the end: the best trials, and with --out the best configuration as a TOML overlay for
`track --config` / `replay --config`, its scores re-measured beside the defaults' on HELD-OUT
worlds (other seeds) and recordings, not the ones tuned on.

Examples:
    photoservo tune --space servo.k_position=0.3:6:log --space servo.feed_forward=0:1 \\
        --worlds 3 --trials 30 --out best.toml --plot tune-plots
    photoservo tune --space-file tune.toml --recordings logs/*.rrd --objectives track,cpu --jobs 2
    photoservo tune ... --storage postgresql://tune@db.lab/photoservo --study gains-v1   # every node
"""

from __future__ import annotations

import argparse
import logging
import math
import time
from typing import Any

from photoservo.cli.config import add_config_options
from photoservo.errors import InputError

log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--space", action="append", default=[], metavar="KEY=LO:HI",
                   help="a tuned key: KEY=LO:HI, KEY=LO:HI:log or KEY=A,B,C (repeatable)")
    p.add_argument("--space-file", metavar="TUNE.toml", help="a TOML file with a [tune.space] table")
    p.add_argument("--worlds", type=int, default=0, metavar="N", help="tune on N generated simulated worlds")
    p.add_argument("--world-from", action="append", default=[], metavar="REC.rrd",
                   help="tune on the world of a simulated recording, closed loop (repeatable)")
    p.add_argument("--recordings", nargs="+", default=[], metavar="REC.rrd",
                   help="tune on these recordings, replayed open loop")
    p.add_argument("--objectives", default="hold", metavar="A,B",
                   help="scores to minimise: hold, track, lost, cpu (several: a Pareto front; default hold)")
    p.add_argument("--weights", metavar="A=W,...", help="one objective: the weighted sum of these scores")
    p.add_argument("--trials", type=int, default=20, metavar="N", help="the study's total trials (default 20)")
    p.add_argument("--study", default="tune", metavar="NAME", help="study name; an existing one continues")
    p.add_argument("--storage", default="tune.db", metavar="URL",
                   help="SQLite file or database URL, e.g. postgresql://user@host/db (default tune.db)")
    p.add_argument("--jobs", type=int, default=1, metavar="N", help="worker processes on this machine")
    p.add_argument("--seed", type=int, default=0,
                   help="the sampler's seed (give each node of a cluster its own); worlds are seeds 1..N, "
                        "held-out ones 1000..")
    p.add_argument("--duration", type=float, default=6.0, metavar="S", help="length of a generated world (s)")
    p.add_argument("--settle", type=float, default=3.0, metavar="S", help="hold error is scored from here (s)")
    p.add_argument("--holdout-worlds", type=int, default=None, metavar="M",
                   help="held-out generated worlds for the final check (default: as many as --worlds, >= 1)")
    p.add_argument("--holdout-recordings", nargs="+", default=None, metavar="REC.rrd",
                   help="held-out recordings (default: the last third of --recordings when there are 2+)")
    p.add_argument("--out", metavar="BEST.toml", help="write the best configuration as a TOML overlay")
    p.add_argument("--plot", metavar="DIR", help="write history/importances/Pareto PNGs into DIR")
    add_config_options(p)


def _objectives(args: argparse.Namespace) -> tuple[tuple[str, ...], tuple[float, ...] | None]:
    if args.weights:
        names, weights = [], []
        for part in args.weights.split(","):
            name, _, w = part.partition("=")
            try:
                weights.append(float(w))
            except ValueError:
                raise InputError(f"--weights '{part}': expected NAME=number") from None
            names.append(name.strip())
        return tuple(names), tuple(weights)
    names = tuple(n.strip() for n in args.objectives.split(",") if n.strip())
    if not names:
        raise InputError("--objectives: empty")
    return names, None


def _sources(args: argparse.Namespace, need_track: bool) -> tuple[Any, Any]:
    """(the runs tuned on, the held-out runs)."""
    from photoservo.tune.objectives import HELDOUT_SEED0, Sources

    for flag in ("worlds", "trials", "jobs"):
        if getattr(args, flag) < (0 if flag == "worlds" else 1):
            raise InputError(f"--{flag} {getattr(args, flag)}: must be >= {0 if flag == 'worlds' else 1}")
    recs, held_recs = list(args.recordings), args.holdout_recordings
    if held_recs is None:
        k = len(recs) // 3 if len(recs) >= 3 else (1 if len(recs) == 2 else 0)
        recs, held_recs = recs[: len(recs) - k], recs[len(recs) - k:]
    common = dict(config_path=args.config, base=tuple(args.overrides), duration_s=args.duration,
                  settle_s=args.settle, need_track=need_track)
    tuned = Sources(world_seeds=tuple(range(1, 1 + args.worlds)),
                    world_from=tuple(args.world_from), recordings=tuple(recs), **common)
    n_held = args.holdout_worlds if args.holdout_worlds is not None else max(1, args.worlds)
    if not tuned.closed_loop:
        n_held = 0
    if n_held < 0:
        raise InputError(f"--holdout-worlds {n_held}: must be >= 0")
    held = None
    if n_held or held_recs:
        held = Sources(world_seeds=tuple(range(HELDOUT_SEED0, HELDOUT_SEED0 + n_held)),
                       recordings=tuple(held_recs), **common)
    return tuned, held


def _start_params(args: argparse.Namespace, space: list) -> dict[str, Any]:
    """The base configuration's values of the tuned keys that lie in the space (the first trial)."""
    from photoservo.config import load_config_dict

    doc = load_config_dict(args.config, args.overrides)
    out = {}
    for p in space:
        node: Any = doc
        for k in p.key.split("."):
            node = node[k]
        if (p.kind == "choice" and node in p.choices) or (p.kind != "choice" and p.low <= node <= p.high):
            out[p.key] = node
    return out


class _Progress:
    """One line per finished trial on stderr, with the best so far and the ETA."""

    def __init__(self, spec: Any, study: Any, jobs: int) -> None:
        from photoservo.tune.study import Progress, count

        self.spec, self.study = spec, study
        self.p = Progress(spec.trials, jobs)
        self.done = count(study)
        self.best: float | None = None

    def __call__(self, r: Any) -> None:
        from photoservo.tune.report import progress_line

        failed = r.values is None
        if not failed:
            self.done += 1
            self.p.seconds.append(r.seconds)
            v = r.values[0]
            self.best = v if self.best is None else min(self.best, v)
        log.info(progress_line(self.done, self.spec.trials, r.number, r.scores, failed, self.best,
                               self.p.eta_s(self.done)))


def run(args: argparse.Namespace) -> int:
    from photoservo.tune.objectives import check_objectives
    from photoservo.tune.runner import Job, run_jobs, stop_after_trial
    from photoservo.tune.space import build_space
    from photoservo.tune.study import StudySpec, _redact, completed, open_study, storage_url

    space = build_space(args.space, args.space_file, args.overrides)
    names, weights = _objectives(args)
    tuned, held = _sources(args, need_track="track" in names)
    check_objectives(names, tuned.closed_loop)
    for src in (tuned, held):
        if src is not None:
            src.check_files()
    spec = StudySpec(args.study, storage_url(args.storage), tuple(space), names, weights, args.trials, args.seed,
                     runs=tuned.describe() + " | " + " ".join(args.overrides))
    study = open_study(spec, _start_params(args, space))
    log.info(f"study '{spec.name}' in {_redact(spec.storage)}: {len(completed(study))}/{spec.trials} trials done\n"
             f"space: {'; '.join(p.describe() for p in space)}\n"
             f"objective{'s (Pareto front)' if spec.pareto else ''}: "
             + (" + ".join(f"{w:g} x {n}" for n, w in zip(names, weights)) if weights else ", ".join(names))
             + f"\ntuned on: {tuned.describe()}")
    t0 = time.monotonic()
    with stop_after_trial() as flag:
        run_jobs(Job(spec, tuned), args.jobs, flag, _Progress(spec, study, args.jobs))
    return _finish(args, spec, study, held, flag.signum, time.monotonic() - t0)


def _finish(args: argparse.Namespace, spec: Any, study: Any, held: Any, signum: int, seconds: float) -> int:
    from photoservo.tune.report import best_table, write_plots
    from photoservo.tune.study import best_trials, completed

    done = completed(study)
    log.info(f"{len(done)}/{spec.trials} trials complete ({seconds:.0f} s this run)")
    if done:
        print(("Pareto front" if spec.pareto else "best trials") + ":\n" + best_table(best_trials(study, spec), spec))
    if signum:
        from photoservo.cli.signals import StopSignal, report_stop

        return report_stop("tune", StopSignal(signum),
                           "stopped after the running trials; the study keeps them (run again to continue)")
    if not done:
        raise InputError(f"--study {spec.name}: every trial failed (see the lines above)")
    if args.plot:
        files = write_plots(study, spec, args.plot)
        log.info("plots: " + ", ".join(str(f) for f in files))
    if args.out:
        _write_best(args, spec, study, held)
    return 0


def _write_best(args: argparse.Namespace, spec: Any, study: Any, held: Any) -> None:
    """Re-measure the best configuration and the defaults on the held-out runs; write --out."""
    from photoservo.fileio import write_text_atomic
    from photoservo.tune.objectives import measure
    from photoservo.tune.report import heldout_table
    from photoservo.tune.space import overlay_toml
    from photoservo.tune.study import best_trial

    best = best_trial(study, spec)
    params = dict(best.params)
    header = [f"# photoservo tune: study '{spec.name}', best trial #{best.number} of {len(study.trials)}",
              f"# objectives: {', '.join(spec.objectives)}; space: {'; '.join(p.describe() for p in spec.space)}"]
    if held is None:
        log.warning("held-out: none (give --holdout-recordings, or 2+ --recordings)")
    else:
        log.info(f"re-measuring the start and trial #{best.number} on held-out runs ...")
        a = measure(held, {})
        b = a if best.user_attrs.get("start") else measure(held, params)   # the start won: the same runs
        table = heldout_table(a, b, held.describe(), spec.objectives[0])
        print(table)
        worse = [n for n in spec.objectives if b.scores.get(n, math.nan) > a.scores.get(n, math.nan)]
        if worse:
            log.warning(f"on the held-out runs the tuned configuration is worse than the start in "
                        f"{', '.join(worse)}: it may fit the tuned runs only (tune on more or longer runs)")
        header += ["#"] + [f"# {line}" for line in table.splitlines()]
    write_text_atomic(args.out, overlay_toml(params, "\n".join(header)))
    log.info(f"best configuration: {args.out}")
