"""The Optuna study behind `photoservo tune` (issue 14): storage, the trial loop of one worker,
the budget shared by every worker, the best trial and its overlay.

Storage: an SQLite file by default (nothing to start); any SQLAlchemy URL that Optuna's RDB
storage takes (`postgresql://user@host/db`) lets many workers on many machines share one study.
Workers ask the storage for a trial, measure it and tell the result; the study's trial budget
(`--trials N`: completed trials) is counted in the storage, so N workers together run N trials,
none twice. A worker stops between trials when asked (Ctrl-C, SIGTERM): the study keeps every
finished trial and a later run with the same --study continues it.

Objectives: a single score, a weighted sum of scores (one objective), or several scores as a
Pareto front (multi-objective TPE). The base configuration's values of the tuned keys are the
first trial of a new study, so the study's best is never worse than the start on the tuned set.
"""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from photoservo.errors import InputError
from photoservo.tune.space import Param

COUNTED = ("COMPLETE", "RUNNING")   # trial states that use the budget (a FAILed trial is re-run)
WORKER = f"{socket.gethostname()}:{os.getpid()}"   # who ran a trial (the trial's user attr "worker")


@dataclass(frozen=True)
class StudySpec:
    """What a study is: its name and storage, the space, the objectives (names; with weights:
    one weighted sum), the trial budget and the sampler's seed."""

    name: str
    storage: str
    space: tuple[Param, ...]
    objectives: tuple[str, ...]
    weights: tuple[float, ...] | None = None
    trials: int = 20
    seed: int = 0
    runs: str = ""      # what a trial runs (the sources and the base config): part of the signature

    @property
    def pareto(self) -> bool:
        return self.weights is None and len(self.objectives) > 1

    def value(self, scores: dict[str, float]) -> list[float]:
        """The objective value(s) Optuna minimises from a trial's scores."""
        if self.weights is not None:
            return [sum(w * scores[n] for n, w in zip(self.objectives, self.weights))]
        return [scores[n] for n in self.objectives]

    def signature(self) -> str:
        """The space and objectives as text: a resumed study must have the same."""
        obj = ",".join(self.objectives) + ("" if self.weights is None else
                                           " weights " + ",".join(f"{w:g}" for w in self.weights))
        return "; ".join(p.describe() for p in self.space) + " | " + obj + (" | " + self.runs if self.runs else "")


def storage_url(text: str) -> str:
    """--storage: a plain file path becomes an SQLite URL; postgresql:// goes through psycopg
    (version 3, the driver we install), whichever driver SQLAlchemy's default is."""
    if "://" not in text:
        return f"sqlite:///{text}"
    if text.startswith(("postgresql://", "postgres://")):
        return "postgresql+psycopg://" + text.split("://", 1)[1]
    return text


def quiet_optuna() -> None:
    """Optuna's own log at warnings only, and no ExperimentalWarning for the features used here
    (heartbeat, multivariate TPE, the matplotlib views): they are what the study needs."""
    import warnings

    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)


def open_storage(url: str) -> Any:
    """Optuna's RDB storage on `url` (heartbeat: a worker that dies mid-trial has its trial
    failed and re-run by the others). A URL it cannot use is an InputError."""
    import optuna
    from sqlalchemy.exc import ArgumentError, DBAPIError

    kwargs: dict[str, Any] = {}
    if url.startswith("sqlite"):
        kwargs["connect_args"] = {"timeout": 60}   # several local workers write to one file
    else:
        kwargs["pool_pre_ping"] = True
    for attempt in range(3):
        try:
            return optuna.storages.RDBStorage(
                url, engine_kwargs=kwargs, heartbeat_interval=10, grace_period=60,
                heartbeat_stale_trial_callback=optuna.storages.RetryHeartbeatStaleTrialCallback(max_retry=2))
        except DBAPIError as e:
            # two workers starting together race to create the schema ("table ... already
            # exists"): the second one's retry finds it made
            if attempt < 2 and "already exists" in str(e):
                time.sleep(0.5 + attempt)
                continue
            raise InputError(f"--storage {_redact(url)}: cannot open ({_first_line(e)})") from None
        except (ArgumentError, ImportError, ModuleNotFoundError, ValueError) as e:
            raise InputError(f"--storage {_redact(url)}: cannot open ({_first_line(e)})") from None
    raise AssertionError("unreachable")


def _first_line(e: BaseException) -> str:
    text = str(e).strip()
    return text.splitlines()[0] if text else type(e).__name__


def _redact(url: str) -> str:
    """The URL without a password (for messages)."""
    if "://" in url and "@" in url:
        head, rest = url.split("://", 1)
        cred, host = rest.rsplit("@", 1)
        return f"{head}://{cred.split(':', 1)[0]}@{host}"
    return url


def open_study(spec: StudySpec, base_params: dict[str, Any] | None = None, worker: int = 0) -> Any:
    """Create the study or load it (resume); a loaded study must have the same space and
    objectives. A new study's first trial is `base_params` (the start). Worker k samples with
    seed + k (workers sharing a storage propose different points)."""
    import optuna

    quiet_optuna()
    sampler = optuna.samplers.TPESampler(seed=spec.seed + worker,
                                         n_startup_trials=max(2, min(10, spec.trials // 3)),
                                         multivariate=True)
    study = optuna.create_study(study_name=spec.name, storage=open_storage(spec.storage),
                                directions=["minimize"] * (len(spec.objectives) if spec.pareto else 1),
                                sampler=sampler, load_if_exists=True)
    sig = study.user_attrs.get("signature")
    if sig is None:
        study.set_user_attr("signature", spec.signature())
        study.set_user_attr("objectives", list(spec.objectives))
        if base_params and not study.trials:
            study.enqueue_trial(base_params, user_attrs={"start": True}, skip_if_exists=True)
    elif sig != spec.signature():
        raise InputError(f"--study {spec.name}: exists in the storage with another space, objectives or runs "
                         f"({sig}); give a new --study name")
    return study


def count(study: Any, below: int | None = None) -> int:
    """Trials that use the budget (complete or running), all or those numbered below `below`."""
    from optuna.trial import TrialState

    states = tuple(TrialState[s] for s in COUNTED)
    trials = study.get_trials(deepcopy=False, states=states)
    return sum(1 for t in trials if below is None or t.number < below)


@dataclass
class TrialResult:
    number: int
    params: dict[str, Any]
    scores: dict[str, float]
    values: list[float] | None      # None: failed (a score was NaN or the run raised)
    seconds: float


def suggest(trial: Any, p: Param) -> Any:
    """The trial's value of one parameter (an enqueued trial gets its fixed value)."""
    if p.kind == "choice":
        return trial.suggest_categorical(p.key, list(p.choices))
    if p.kind == "int":
        return trial.suggest_int(p.key, int(p.low), int(p.high), log=p.log)
    return trial.suggest_float(p.key, float(p.low), float(p.high), log=p.log)


def run_worker(study: Any, spec: StudySpec, measure: Callable[[dict[str, Any]], dict[str, float]],
               stop: Callable[[], bool], on_trial: Callable[[TrialResult], None] | None = None) -> int:
    """Run trials until the study's budget is used or `stop()` (checked between trials; the
    running trial finishes). A trial whose run raises a ValueError (InputError included) or
    RuntimeError, or scores NaN, is FAILed and does not use the budget. The storage's heartbeat
    fails the trial of a worker that died; the others re-run it. More failed trials than the
    budget stop the worker. Returns the number of trials this worker failed."""
    import optuna

    failed: list[int] = []
    if stop() or count(study) >= spec.trials:
        return 0

    def objective(trial: Any) -> float | list[float]:
        if count(study, below=trial.number) >= spec.trials:   # another worker took the last one
            study.stop()
            raise optuna.TrialPruned("the study's trial budget is used")
        params = {p.key: suggest(trial, p) for p in spec.space}
        trial.set_user_attr("worker", WORKER)
        t0 = time.perf_counter()
        scores = measure(params)
        trial.set_user_attr("scores", scores)
        trial.set_user_attr("seconds", time.perf_counter() - t0)
        values = spec.value(scores)
        return values if len(values) > 1 else values[0]

    def after(st: Any, frozen: Any) -> None:
        if on_trial is not None and frozen.state.name != "PRUNED":
            on_trial(TrialResult(frozen.number, dict(frozen.params), frozen.user_attrs.get("scores", {}),
                                 frozen.values, float(frozen.user_attrs.get("seconds", float("nan")))))
        if frozen.state.name == "FAIL":
            failed.append(frozen.number)
        if stop() or count(st) >= spec.trials or len(failed) > spec.trials:
            st.stop()

    study.optimize(objective, callbacks=[after], catch=(ValueError, RuntimeError, FloatingPointError),
                   gc_after_trial=False)
    return len(failed)


def completed(study: Any) -> list[Any]:
    from optuna.trial import TrialState

    return study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))


def best_trials(study: Any, spec: StudySpec, k: int = 5) -> list[Any]:
    """Single objective: the k best completed trials; Pareto: the front, best first objective first."""
    if spec.pareto:
        return sorted(study.best_trials, key=lambda t: t.values[0])
    return sorted(completed(study), key=lambda t: t.value)[:k]


def best_trial(study: Any, spec: StudySpec) -> Any:
    """The trial whose parameters go into --out: the best (single objective), or the Pareto
    front's best in the first objective."""
    best = best_trials(study, spec, 1)
    if not best:
        raise InputError(f"--study {spec.name}: no completed trial yet")
    return best[0]


@dataclass
class Progress:
    """Trial times and the ETA of the remaining budget with `jobs` workers."""

    total: int
    jobs: int = 1
    start_done: int = 0
    seconds: list[float] = field(default_factory=list)

    def eta_s(self, done: int) -> float:
        if not self.seconds:
            return float("nan")
        per = sorted(self.seconds)[len(self.seconds) // 2]
        return max(0, self.total - done) * per / max(1, self.jobs)
