"""Comparing two runs (issue 6): the side-by-side table `photoservo replay` and
`track --world-from` print — mean fitness, found ratio, pose jitter, lost frames, time per
frame, commanded motion and, when both runs carry the simulator's ground truth, track /
heading / tilt / size / hold error. Definitions at `run_metrics` and servo/scores.py.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from photoservo.errors import InputError
from photoservo.record.reader import EstimateRecord, Recording, TruthRecord, read_recording
from photoservo.servo.scores import HoldSample, commanded_motion, hold_sample, jitter_mm, rms, scored_holds, \
    track_error_mm


def _heading_tilt(T: np.ndarray) -> tuple[float, float]:
    """Heading: direction of the model x axis in the base xy plane (rad). Tilt: angle of the
    model z axis from the base vertical (rad, 0..pi/2, sign of z ignored)."""
    x, z = T[:3, 0], T[:3, 2]
    return math.atan2(x[1], x[0]), math.acos(min(1.0, abs(float(z[2]) / np.linalg.norm(z))))


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def run_metrics(rec: Recording) -> dict[str, float]:
    """Per-run numbers of the comparison table (NaN when a run lacks the data); the scores
    (hold error, track error, jitter, commanded motion) are defined in servo/scores.py:

    frames            frames logged
    mean_fitness      mean fitness over all estimates that have a finite one (a frame the tracker
                      searched and found nothing on logs -inf)
    found_ratio       estimates with found / estimates
    lost_frames       estimates with found = false
    jitter_mm         jitter of the estimated position (base frame when the camera pose was
                      logged) over consecutive found frames
    ms_per_frame      (t_last - t_first) / (frames - 1) * 1000 on the loop clock
    tracker_ms        mean hue + mean GA time per frame (timing/hue_ms, timing/ga_ms): the
                      processing cost, which a replay changes while its frame times do not
    commanded_rad_s   commanded motion of the recorded velocity commands (arm/command_deg_s)
    track_err_mm      RMS track error over found frames with truth
    heading_err_deg   RMS heading difference (model x axis in the base xy plane, wrapped)
    tilt_err_deg      RMS difference of tilt (model z axis from the vertical)
    size_err_mm       RMS over found frames of the mean |size_est - size_true| of the 2 sides
    hold_err_mm       the hold score (servo/scores.py, what `track --json` prints as
                      hold_error_rms_mm): RMS hold error over the frames with truth and a camera
                      pose captured from [servo] settle_s on while the controller servoed (the
                      recorded phase events); hover_mm and settle_s from the recorded config,
                      the rig from the recorded rig
    hold_yaw_err_deg  the same frames' RMS hold yaw error (`hold_yaw_error_rms_deg`)
    """
    nan = float("nan")
    est = rec.estimates
    found = [e for e in est if e.found and e.T_base_model() is not None]
    m: dict[str, float] = {"frames": float(len(rec.frames))}
    fits = [e.fitness for e in est if e.fitness is not None and math.isfinite(e.fitness)]
    m["mean_fitness"] = float(np.mean(fits)) if fits else nan
    m["found_ratio"] = len([e for e in est if e.found]) / len(est) if est else nan
    m["lost_frames"] = float(len([e for e in est if not e.found])) if est else nan
    runs = [(a, b, c) for a, b, c in zip(found, found[1:], found[2:])
            if b.frame == a.frame + 1 and c.frame == b.frame + 1]
    m["jitter_mm"] = rms([jitter_mm([e.T_base_model()[:3, 3] for e in r]) for r in runs]) if runs else nan
    ts = [f.t for f in rec.frames]
    m["ms_per_frame"] = (ts[-1] - ts[0]) / (len(ts) - 1) * 1000 if len(ts) > 1 else nan
    if "hue" in rec.timings and "ga" in rec.timings:
        m["tracker_ms"] = float(np.mean(rec.timings["hue"].values) + np.mean(rec.timings["ga"].values))
    else:
        m["tracker_ms"] = nan
    cmd = rec.arm.get("command")
    m["commanded_rad_s"] = commanded_motion(cmd.values) if cmd is not None else nan
    truth = {tr.frame: tr for tr in rec.truth}
    m.update(_truth_errors(found, truth))
    held = _holds(rec, truth)
    m["hold_err_mm"] = rms([h.error_mm for h in held])
    m["hold_yaw_err_deg"] = rms([h.yaw_deg for h in held])
    return m


def _truth_errors(found: list[EstimateRecord], truth: dict[int, TruthRecord]) -> dict[str, float]:
    """RMS track, heading, tilt and size errors of found estimates against the truth (see
    `run_metrics`)."""
    pos, head, tilt, size = [], [], [], []
    for e in found:
        tr = truth.get(e.frame)
        if tr is None:
            continue
        Te, Tt = e.T_base_model(), tr.T_base_target
        pos.append(track_error_mm(Te[:3, 3], Tt[:3, 3]))
        (he, te), (ht, tt) = _heading_tilt(Te), _heading_tilt(Tt)
        head.append(_wrap(he - ht))
        tilt.append(te - tt)
        if e.size_mm is not None and tr.size_mm is not None:
            size.append(float(np.mean(np.abs(e.size_mm - tr.size_mm))))
    return {"track_err_mm": rms(pos), "heading_err_deg": rms(head) * 180 / math.pi,
            "tilt_err_deg": rms(tilt) * 180 / math.pi, "size_err_mm": rms(size)}


def _holds(rec: Recording, truth: dict[int, TruthRecord]) -> list[HoldSample]:
    """The holds the hold score counts (servo/scores.scored_holds) of the frames with truth and
    a camera pose, at their capture times, by the recorded config and phase events."""
    import tomllib

    from photoservo.config import load_config
    from photoservo.servo.controller import left_centre
    try:
        rig = rec.setup.rig()
        servo = load_config(recorded=("recording", tomllib.loads(rec.setup.config_toml or ""))).servo
    except (TypeError, ValueError, InputError):
        return []
    if rig is None:
        return []
    centre = left_centre(rig)
    samples = [hold_sample((f.capture_times or (f.t,))[0], f.T_base_left, centre, truth[f.index].T_base_target,
                           tuple(truth[f.index].size_mm), servo.hover_mm)
               for f in rec.frames if f.index in truth and f.T_base_left is not None
               and truth[f.index].size_mm is not None]
    return scored_holds(samples, [(t, text) for t, _, text in rec.events], servo.settle_s)


METRICS: tuple[tuple[str, str, str], ...] = (
    ("frames", "frames", "{:.0f}"),
    ("mean_fitness", "mean fitness", "{:.4f}"),
    ("found_ratio", "found ratio", "{:.3f}"),
    ("lost_frames", "lost frames", "{:.0f}"),
    ("jitter_mm", "pose jitter (mm)", "{:.2f}"),
    ("ms_per_frame", "time per frame (ms)", "{:.1f}"),
    ("tracker_ms", "tracker ms per frame", "{:.1f}"),
    ("commanded_rad_s", "commanded motion (rad/s)", "{:.3f}"),
    ("track_err_mm", "track error vs truth (mm RMS)", "{:.2f}"),
    ("heading_err_deg", "heading error (deg RMS)", "{:.2f}"),
    ("tilt_err_deg", "tilt error (deg RMS)", "{:.2f}"),
    ("size_err_mm", "size error (mm RMS)", "{:.2f}"),
    ("hold_err_mm", "hold error vs truth (mm RMS)", "{:.2f}"),
    ("hold_yaw_err_deg", "hold yaw error vs truth (deg RMS)", "{:.2f}"),
)


@dataclass
class ComparisonRow:
    key: str
    label: str
    a: float
    b: float

    @property
    def delta(self) -> float:
        return self.b - self.a


@dataclass
class Comparison:
    """Side-by-side numbers of two runs; `str()` is the table replay prints."""

    name_a: str
    name_b: str
    rows: list[ComparisonRow]

    def row(self, key: str) -> ComparisonRow:
        return next(r for r in self.rows if r.key == key)

    def __str__(self) -> str:
        fmt = {k: f for k, _, f in METRICS}

        def cell(v: float, key: str) -> str:
            return "-" if math.isnan(v) else fmt[key].format(v)
        head = ("", self.name_a, self.name_b, "B - A")
        body = [(r.label, cell(r.a, r.key), cell(r.b, r.key), cell(r.delta, r.key)) for r in self.rows]
        w = [max(len(x[i]) for x in [head, *body]) for i in range(4)]
        line = lambda x: "  ".join([x[0].ljust(w[0])] + [x[i].rjust(w[i]) for i in (1, 2, 3)])
        return "\n".join([line(head), "  ".join("-" * n for n in w), *map(line, body)])


def compare_runs(a: Recording | str | Path, b: Recording | str | Path, name_a: str = "A",
                 name_b: str = "B") -> Comparison:
    """The comparison table of two runs (replay vs recorded, or two closed-loop runs), given
    as recordings read or as paths. Truth rows are NaN ('-') unless the runs carry truth."""
    a, b = (r if isinstance(r, Recording) else read_recording(r) for r in (a, b))
    ma, mb = run_metrics(a), run_metrics(b)
    return Comparison(name_a, name_b, [ComparisonRow(k, lbl, ma[k], mb[k]) for k, lbl, _ in METRICS])
