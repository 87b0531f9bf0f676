"""What a tuning trial measures (issue 14): one configuration run on simulated worlds (closed
loop, lockstep: servo, tracker and GA keys all act) and/or replayed recordings (open loop through
`record.replay`: tracker and GA keys act, photo-model keys on full recordings; the arm's path is the recorded one), scored
with the session's own numbers. Every score is "lower is better":

  hold   hold error (mm RMS, servo/scores.py): the rig centre against hover_mm over the TRUE
         target at each frame, after settling (the lockstep session's `Scores`, what
         `track --json` prints as hold_error_rms_mm and replay's table as its hold row);
         closed loop only: a replay does not move the arm
  track  track error (mm RMS): estimated target position against the truth, found frames
         (`record.compare.run_metrics` track_err_mm of the run's recording)
  lost   share of frames whose estimate was not found (0..1)
  cpu    tracker time per frame (ms): hue + GA, mean over frames (wall time of the loop's
         vision step; on a loaded machine it carries the load)

This module is the ONE place where tuning turns a run into these numbers (`session_scores`,
`recording_scores`), read from the definitions in servo/scores.py (the summary, the table).

World generator (`world_overrides`): a seed makes a world - the simulator's own seed (textures,
waves, noise) and, drawn from it, the target's start, heading and drift and the arm's start
offset - so held-out worlds differ from the tuned ones in more than noise.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from photoservo.config import Config, load_config
from photoservo.errors import InputError
from photoservo.tune.space import overrides

OBJECTIVES: dict[str, str] = {
    "hold": "hold error (mm RMS)",
    "track": "track error (mm RMS)",
    "lost": "lost frame share",
    "cpu": "tracker ms per frame",
}
HELDOUT_SEED0 = 1000   # held-out worlds are seeds 1000, 1001, ... (tuned ones are 1..N)


def world_overrides(seed: int) -> list[str]:
    """The world of seed `seed` as --set overrides (module docstring): the simulator seed, the
    target's start (x 600..800, y -100..100 mm), heading (0..180 deg), drift (10..40 mm/s in any
    direction) and the arm's start offset (100..200 mm) and yaw (-15..15 deg)."""
    rng = np.random.default_rng([seed, 14])
    x, y = rng.uniform(600.0, 800.0), rng.uniform(-100.0, 100.0)
    speed, direction = rng.uniform(10.0, 40.0), rng.uniform(0.0, 2 * math.pi)
    return [f"sim.seed={seed}", f"sim.target_start_mm=[{x:.1f}, {y:.1f}]",
            f"sim.heading_deg={rng.uniform(0.0, 180.0):.1f}",
            f"sim.drift_mm_s=[{speed * math.cos(direction):.2f}, {speed * math.sin(direction):.2f}]",
            f"sim.start_offset_mm={rng.uniform(100.0, 200.0):.1f}",
            f"sim.start_yaw_deg={rng.uniform(-15.0, 15.0):.1f}", "sim.lockstep=true"]


@dataclass(frozen=True)
class Sources:
    """What one trial runs: generated worlds (seeds), recorded worlds (--world-from), recordings
    (replay), with the base configuration (--config, --set) under the trial's parameters."""

    config_path: str | None = None
    base: tuple[str, ...] = ()
    world_seeds: tuple[int, ...] = ()
    world_from: tuple[str, ...] = ()
    recordings: tuple[str, ...] = ()
    duration_s: float = 6.0
    settle_s: float = 3.0
    need_track: bool = False    # record the closed-loop runs to score track error (costs time)

    def __post_init__(self) -> None:
        if not (self.world_seeds or self.world_from or self.recordings):
            raise InputError("nothing to tune on: give --worlds N, --world-from REC or --recordings REC ...")
        if self.world_seeds and not 0 <= self.settle_s < self.duration_s:
            raise InputError(f"--settle {self.settle_s}: must be in 0..--duration ({self.duration_s} s)")

    def check_files(self) -> None:
        """Every recording exists (a one-line error before the study, not after it)."""
        for p in (*self.world_from, *self.recordings):
            if not Path(p).is_file():   # a recording is one file (record/recorder.py)
                raise InputError(f"{p}: recording not found")

    @property
    def closed_loop(self) -> bool:
        return bool(self.world_seeds or self.world_from)

    def describe(self) -> str:
        parts = []
        if self.world_seeds:
            s = self.world_seeds
            parts.append(f"{len(s)} world{'s' * (len(s) > 1)} (seeds {s[0]}..{s[-1]}, "
                         f"{self.duration_s:g} s, hold scored after {self.settle_s:g} s)")
        if self.world_from:
            parts.append(f"{len(self.world_from)} recorded world(s) ({', '.join(Path(p).name for p in self.world_from)})")
        if self.recordings:
            parts.append(f"{len(self.recordings)} recording(s) replayed "
                         f"({', '.join(Path(p).name for p in self.recordings)})")
        return "; ".join(parts)


def session_scores(summary: dict) -> dict[str, float]:
    """hold, lost, cpu of a closed-loop run from its `Scores.summary()` (what `track --json`
    prints): the run's own numbers. cpu is the mean stage time when the summary has it (tune's
    runs), else the median `track --json` prints."""
    frames = summary["frames"]
    t = summary.get("timings_ms_mean") or summary.get("timings_ms_median") or {}
    hold = summary.get("hold_error_rms_mm")
    return {"hold": float("nan") if hold is None else float(hold),   # strict JSON: null when there is none
            "lost": (frames - round(summary["found_ratio"] * frames)) / frames if frames else float("nan"),
            "cpu": float(t.get("hue", float("nan")) + t.get("ga", float("nan")))}


def recording_scores(metrics: dict[str, float]) -> dict[str, float]:
    """track, lost, cpu of a run from its recording's `run_metrics` (replay's table)."""
    frames = metrics["frames"]
    return {"track": float(metrics["track_err_mm"]),
            "lost": metrics["lost_frames"] / frames if frames else float("nan"),
            "cpu": float(metrics["tracker_ms"])}


def _lockstep(cfg: Config, duration_s: float, seed: int, settle_s: float, need_track: bool) -> dict[str, float]:
    """One closed-loop lockstep run -> scores (recorded to a temporary file for track error); the
    hold is scored from settle_s ([servo] settle_s of the run)."""
    from photoservo.record.compare import run_metrics
    from photoservo.record.reader import read_recording
    from photoservo.sim.run import build_sim, run_lockstep

    cfg = dataclasses.replace(cfg, servo=dataclasses.replace(cfg.servo, settle_s=settle_s))
    sim = build_sim(cfg)
    if not need_track:
        sc = run_lockstep(cfg, duration_s, seed=seed, setup=sim)
        return session_scores(_summary(sc))
    from photoservo.record.recorder import Recorder
    from photoservo.tomlconf import dump_config
    from photoservo.vision.rig import dump_rig

    with tempfile.TemporaryDirectory(prefix="photoservo-tune-") as tmp:
        path = Path(tmp) / "run.rrd"
        rec = Recorder.from_config(cfg.recording, "tune", path)
        try:
            rec.log_static_setup(dump_rig(sim.rig), sim.scene.photo, sim.scene.model, dump_config(cfg),
                                 {"tracker": seed, "sim": cfg.sim.seed})
            sc = run_lockstep(cfg, duration_s, seed=seed, setup=sim, recorder=rec)
        finally:
            rec.close()
        scores = session_scores(_summary(sc))
        scores["track"] = recording_scores(run_metrics(read_recording(path)))["track"]
    return scores


def _summary(sc: Any) -> dict:
    """`Scores.summary()` with the mean stage times (the tracker cost is a mean per frame)."""
    s = sc.summary()
    s["timings_ms_mean"] = {k: float(np.mean(v)) for k, v in sc.timings_ms.items()}
    return s


def world_scores(src: Sources, params: dict[str, Any], seed: int) -> dict[str, float]:
    """The scores of a generated world (seed) with the trial's parameters on the base config."""
    cfg = load_config(src.config_path, [*world_overrides(seed), *src.base, *overrides(params)])
    return _lockstep(cfg, src.duration_s, seed, src.settle_s, src.need_track)


def world_from_scores(src: Sources, params: dict[str, Any], path: str) -> dict[str, float]:
    """The scores of a recorded simulated world (`track --world-from`), closed loop, with the
    trial's parameters on top of the recorded config."""
    import dataclasses

    from photoservo.record.replay import world_from

    w = world_from(path, src.config_path, [*src.base, *overrides(params)])
    cfg = dataclasses.replace(w.cfg, sim=dataclasses.replace(w.cfg.sim, lockstep=True))
    return _lockstep(cfg, w.duration_s, w.seed, min(src.settle_s, 0.5 * w.duration_s), src.need_track)


def replay_scores(src: Sources, params: dict[str, Any], path: str) -> dict[str, float]:
    """The scores of a recording replayed (open loop) with the trial's parameters."""
    from photoservo.record.replay import load_replay, replay

    setup = load_replay(path, src.config_path, [*src.base, *overrides(params)])
    with tempfile.TemporaryDirectory(prefix="photoservo-tune-") as tmp:
        result = replay(setup, Path(tmp) / "replay.rrd")
    return recording_scores({r.key: r.b for r in result.comparison.rows})


@dataclass
class Measurement:
    """A configuration's scores: the mean over the runs that define each score, and each run's."""

    scores: dict[str, float]
    runs: list[tuple[str, dict[str, float]]] = field(default_factory=list)


def measure(src: Sources, params: dict[str, Any]) -> Measurement:
    """Run every world and recording of `src` with `params`; the mean of each score over the
    runs that define it (NaN when none does)."""
    runs: list[tuple[str, dict[str, float]]] = []
    for seed in src.world_seeds:
        runs.append((f"world {seed}", world_scores(src, params, seed)))
    for p in src.world_from:
        runs.append((f"world from {Path(p).name}", world_from_scores(src, params, p)))
    for p in src.recordings:
        runs.append((f"replay {Path(p).name}", replay_scores(src, params, p)))
    scores = {}
    for name in OBJECTIVES:
        vals = [r[name] for _, r in runs if name in r and not math.isnan(r[name])]
        scores[name] = float(np.mean(vals)) if vals else float("nan")
    return Measurement(scores, runs)


def check_objectives(names: Sequence[str], closed_loop: bool) -> None:
    """Every objective is a known score that the runs (closed loop: worlds) can measure."""
    for n in names:
        if n not in OBJECTIVES:
            raise InputError(f"objective '{n}': not one of {', '.join(OBJECTIVES)}")
        if n == "hold" and not closed_loop:
            raise InputError("objective 'hold' needs a closed loop (--worlds N or --world-from REC): "
                             "a replay does not move the arm")
