"""What `photoservo tune` prints and writes (issue 14): the table of the best trials, the
held-out comparison of the defaults and the tuned configuration, the progress line, and the
`--plot` PNGs (Optuna's matplotlib views: optimisation history, parameter importances, Pareto
front)."""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from photoservo.tune.objectives import OBJECTIVES
from photoservo.tune.study import StudySpec


def _num(v: Any, nd: int = 3) -> str:
    if isinstance(v, float):
        if math.isnan(v):
            return "-"
        return f"{v:.{nd}g}" if abs(v) < 10 ** nd else f"{v:.0f}"
    return str(v)


def _table(head: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    w = [max(len(r[i]) for r in [head, *rows]) for i in range(len(head))]
    line = lambda r: "  ".join(c.rjust(w[i]) if i else c.ljust(w[i]) for i, c in enumerate(r))  # noqa: E731
    return "\n".join([line(head), "  ".join("-" * n for n in w), *map(line, rows)])


def best_table(trials: Sequence[Any], spec: StudySpec) -> str:
    """Trial number, objective value(s), every measured score and the parameters."""
    names = [n for n in OBJECTIVES
             if any(not math.isnan(t.user_attrs.get("scores", {}).get(n, float("nan"))) for t in trials)]
    keys = [p.key for p in spec.space]
    value_head = ["value"] if not spec.pareto else []
    head = ["trial", *value_head, *names, *keys]
    rows = []
    for t in trials:
        sc = t.user_attrs.get("scores", {})
        start = " (start)" if t.user_attrs.get("start") else ""
        rows.append([f"#{t.number}{start}", *([_num(t.value, 4)] if not spec.pareto else []),
                     *(_num(sc.get(n, float("nan"))) for n in names),
                     *(_num(t.params.get(k, "-"), 4) for k in keys)])
    return _table(head, rows)


def heldout_table(start: Any, tuned: Any, what: str, first: str) -> str:
    """The scores of the start (the base config: defaults <- --config <- --set) and of the tuned
    overlay on held-out runs (two objectives.Measurement), side by side: every score's mean,
    then the first objective run by run."""
    rows = []
    for n, label in OBJECTIVES.items():
        a, b = start.scores.get(n, float("nan")), tuned.scores.get(n, float("nan"))
        if not (math.isnan(a) and math.isnan(b)):
            rows.append([label, _num(a), _num(b), _ratio(a, b)])
    for (name, ra), (_, rb) in zip(start.runs, tuned.runs):
        a, b = ra.get(first, float("nan")), rb.get(first, float("nan"))
        if not (math.isnan(a) and math.isnan(b)):
            rows.append([f"  {first}: {name}", _num(a), _num(b), _ratio(a, b)])
    return f"held-out: {what}\n" + _table(["", "start", "tuned", "tuned/start"], rows)


def _ratio(a: float, b: float) -> str:
    return _num(b / a, 2) if a and not (math.isnan(a) or math.isnan(b)) else "-"


def progress_line(done: int, total: int, number: int, scores: dict[str, float], failed: bool,
                  best: float | None, eta_s: float) -> str:
    """'trial 4/20 (#3): hold 6.2, lost 0, cpu 83 | best 5.9 | ETA 2.5 min'."""
    if failed:
        body = "failed"
    else:
        body = ", ".join(f"{n} {_num(v)}" for n, v in scores.items() if not math.isnan(v))
    eta = ("-" if math.isnan(eta_s) else f"{eta_s:.0f} s" if eta_s < 120 else f"{eta_s / 60:.1f} min")
    best_s = "" if best is None else f" | best {_num(best, 4)}"
    return f"trial {done}/{total} (#{number}): {body}{best_s} | ETA {eta}"


def write_plots(study: Any, spec: StudySpec, folder: str | Path) -> list[Path]:
    """history.png, importances.png (two or more parameters) and pareto.png (several objectives)
    in `folder`; returns the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from optuna.visualization import matplotlib as ovm

    from photoservo.fileio import write_bytes_atomic

    out = Path(folder)
    first = spec.objectives[0] if spec.pareto else ("weighted sum" if spec.weights else spec.objectives[0])
    label = OBJECTIVES.get(first, first)
    target = (lambda t: t.values[0]) if spec.pareto else None
    views: list[tuple[str, Any]] = [
        ("history.png", lambda: ovm.plot_optimization_history(study, target=target, target_name=label))]
    if len(spec.space) >= 2:
        views.append(("importances.png", lambda: ovm.plot_param_importances(study, target=target, target_name=label)))
    if spec.pareto:
        names = [OBJECTIVES[n] for n in spec.objectives]
        views.append(("pareto.png", lambda: ovm.plot_pareto_front(study, target_names=names)))
    written = []
    for name, make in views:
        with warnings.catch_warnings():   # the importance evaluator's note that lower is better: it is
            warnings.simplefilter("ignore", UserWarning)
            ax = make()
        fig = (ax if hasattr(ax, "savefig") else ax.figure if hasattr(ax, "figure") else ax.flat[0].figure)
        fig.set_size_inches(8, 5)
        fig.tight_layout()
        import io

        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=110)
        plt.close(fig)
        write_bytes_atomic(out / name, buf.getvalue())
        written.append(out / name)
    return written
