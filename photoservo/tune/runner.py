"""Workers of one `photoservo tune` run (issue 14): this process alone (--jobs 1), or N worker
processes on this machine sharing the study's storage (--jobs N; spawn: each has its own
interpreter and compiled kernels, so N cores work). Each worker runs `study.run_worker`; the
parent only starts them, relays their finished trials (for the progress line) and, on Ctrl-C or
SIGTERM, asks them to stop after their running trial.

A stop is a flag, not an exception: the running trial finishes and is stored; a second signal
interrupts at once (that trial is then FAILed, and re-run by a later run).
"""

from __future__ import annotations

import multiprocessing
import os
import queue
import signal
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from photoservo.tune.objectives import Sources, measure
from photoservo.tune.study import StudySpec, TrialResult, open_study, run_worker

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@dataclass
class StopFlag:
    """Set by the first SIGINT/SIGTERM/SIGHUP (which one: `signum`); the second raises
    KeyboardInterrupt."""

    signum: int = 0

    def __call__(self) -> bool:
        return self.signum != 0


@contextmanager
def stop_after_trial(escalate: bool = True) -> Iterator[StopFlag]:
    """Within the block the stop signals set the returned flag (the first) or interrupt (a
    second one, with `escalate`; a worker process does not escalate: Ctrl-C reaches it and the
    parent's forwarded SIGTERM too); the previous handlers come back on exit."""
    flag = StopFlag()

    def handler(signum: int, frame: object) -> None:
        if flag.signum:
            if escalate:
                raise KeyboardInterrupt
            return
        flag.signum = signum

    old = {s: signal.signal(s, handler) for s in STOP_SIGNALS}
    try:
        yield flag
    finally:
        for s, h in old.items():
            signal.signal(s, h)


@dataclass(frozen=True)
class Job:
    """What a worker needs (picklable: it crosses to a spawned process)."""

    spec: StudySpec
    sources: Sources
    worker: int = 0

    def measure(self, params: dict[str, Any]) -> dict[str, float]:
        return measure(self.sources, params).scores


def _worker_process(job: Job, results: Any) -> None:
    """A spawned worker: its own study handle and sampler seed, results to the parent."""
    with stop_after_trial(escalate=False) as flag:
        study = open_study(job.spec, worker=job.worker)
        run_worker(study, job.spec, job.measure, flag, results.put)


def run_jobs(job: Job, jobs: int, flag: StopFlag, on_trial: Callable[[TrialResult], None]) -> None:
    """Run the study's remaining budget with `jobs` workers (this process when 1). `flag` is
    the caller's stop flag; when it is set the workers are asked to stop after their trial."""
    if jobs <= 1:
        run_worker(open_study(job.spec), job.spec, job.measure, flag, on_trial)
        return
    ctx = multiprocessing.get_context("spawn")
    results = ctx.Queue()
    procs = [ctx.Process(target=_worker_process, args=(Job(job.spec, job.sources, k), results), daemon=True)
             for k in range(jobs)]
    for p in procs:
        p.start()
    forwarded = False
    try:
        while any(p.is_alive() for p in procs) or not results.empty():
            if flag() and not forwarded:
                for p in procs:
                    if p.pid is not None and p.is_alive():
                        os.kill(p.pid, signal.SIGTERM)
                forwarded = True
            try:
                on_trial(results.get(timeout=0.2))
            except queue.Empty:
                pass
    finally:
        for p in procs:
            p.join(timeout=5)
            if p.is_alive():
                p.terminate()
                p.join()
    failed = [p.exitcode for p in procs if p.exitcode not in (0, None)]
    if failed and not flag():
        raise RuntimeError(f"{len(failed)} of {jobs} tune workers failed (exit codes {failed})")
