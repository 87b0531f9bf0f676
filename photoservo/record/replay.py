"""Replay (issue 6): re-run a recorded session's estimator and control law from its `.rrd` alone,
with a changed config, and compare the two runs; and the same simulated world in closed loop
(`photoservo track --sim --world-from REC`).

Replay (`replay`), from the file alone:
  * setup: the recorded rig (TOML), the photo-model (bit-exact arrays), the tracker seed and the
    effective config; the config replay runs with is defaults <- recorded <- --config <- --set
    (`load_replay`).
  * vision: every recorded stereo frame (read back exactly: a full recording's pixels, or a
    compact recording's planes — the hue classes and grey the tracker reads, `record.planes`;
    a preview recording is refused) goes through a fresh `vision.tracker.Tracker` with
    the recorded seed, at its recorded capture time and left-camera pose T_base_left, with no
    time budget. Generation counts: a lockstep recording (config sim.lockstep = true) ran the
    fixed [tracker] generations_per_frame, and so does its replay. A real-time run stopped
    frames by its time budget; its replay runs each tracking frame for the generation count
    recorded for that frame ("recorded counts"), unless the replay changes
    tracker.generations_per_frame or asks for `fixed_generations`. Either way the replay is
    deterministic: same recording + same config = same result, frame for frame.
  * control, OPEN LOOP: the recorded joint states (arm/q, linearly interpolated between its
    samples; dq by finite differences) drive a fresh `servo.controller.Controller` at the control rate
    ([motion] rate_hz) with the replayed track, which becomes available at capture time +
    [sim] capture_latency_s, as in the lockstep session (for a real-time recording, + the
    frame's recorded hue + GA time, when its track reached the control thread). What it would have commanded is
    logged as arm/setpoint_q (rad) and arm/setpoint_dq (rad/s), as the session logs them, beside
    the recorded q. The arm does not move: servo gains change the commands, not the frames, so
    tune gains closed loop with `track --sim --world-from REC`.
  * keys: a compact recording replays any tracker, GA, estimator, fitness-weight and servo key
    exactly as the full frames would; photo_model.* and the hue keys (`planes.HUE_KEYS`)
    change what the tracker reads, so only a full recording lets them change (the photo-model
    is then rebuilt from the recorded photo). A truncated recording (its writer was killed)
    is refused with what is missing and how much was read, unless `allow_partial`.
  * output: a complete recording (static setup with the replay's effective config and the
    same seed, every frame again, estimates, truth copied, arm series, timings, events; a
    compact recording's video copied) that can itself be replayed, and the side-by-side table
    (`compare.compare_runs`); `record=False` keeps no recording.

World from a recording (`world_from`): a simulated recording's effective config (its [sim]
section: seed, target motion, cameras) and tracker seed rebuilt, the user's --config/--set on
top (new gains), and the session re-run closed loop; `track` then prints the comparison table.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
import tomllib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from photoservo.errors import InputError
from photoservo.config import Config, load_config
from photoservo.record.compare import Comparison, compare_runs
from photoservo.record.reader import Frame, Recording, describe_truncation, iter_frames, read_recording
from photoservo.robot.arm import JointHistory
from photoservo.tomlconf import dump_config

# ------------------------------------------------------------------------------------------
# the setup from the file


@dataclass
class ReplaySetup:
    """Everything a replay starts from, rebuilt from a recording (+ config changes)."""

    path: Path
    recording: Recording
    recorded_cfg: Config          # the config the recorded run ran with
    cfg: Config                   # recorded <- --config <- --set: what the replay runs with
    rig: Any                      # vision.rig.Rig with [hand_eye]
    model: Any                    # vision.photo_model.PhotoModel (bit-exact)
    photo: np.ndarray | None
    seed: int                     # the tracker seed
    recorded_generations: bool    # run tracking frames for their recorded generation counts

    @property
    def generations_note(self) -> str:
        n = self.cfg.tracker.generations_per_frame
        if self.recorded_generations:
            return ("recorded generation counts per tracking frame, at most "
                    f"{n} (a real-time run: recorded sim.lockstep = false; its time budget may have "
                    "stopped frames early)")
        return f"fixed {n} generations per tracking frame (no time budget)"


def _read(p: Path, allow_partial: bool) -> Recording:
    """`read_recording` with one-line InputErrors: a missing or unreadable file, and a
    truncated one (what is missing, how much was read) unless `allow_partial`, when that line
    is a warning on stderr instead."""
    try:
        rec = read_recording(p)
    except InputError:
        raise
    except (OSError, ValueError, RuntimeError) as e:
        raise InputError(f"{p}: not a readable recording ({_first_line(e)})") from None
    if rec.truncated is not None:
        if not allow_partial:
            raise InputError(describe_truncation(rec) + "; --allow-partial uses what is there")
        print(f"warning: {describe_truncation(rec)}; using what is there (--allow-partial)", file=sys.stderr)
    return rec


def read_checked(path: str | Path, allow_partial: bool = False) -> Recording:
    """`read_recording` with one-line errors: a missing, unreadable, truncated (unless
    `allow_partial`) or non-photoservo file is an InputError; a preview-mode (video only)
    recording cannot be replayed."""
    p = Path(path)
    rec = _read(p, allow_partial)
    if not rec.setup.replayable:
        raise InputError(f"{p}: a preview recording (a lossy video of the frames) cannot be replayed")
    return rec


def _first_line(x: Any) -> str:
    s = str(x).strip()
    return s.splitlines()[0] if s else type(x).__name__


def recorded_config(rec: Recording, path: str | Path, config_path: str | Path | None = None,
                    overrides: Sequence[str] = ()) -> tuple[Config, Config]:
    """(the recorded run's config, the config to run with = defaults <- recorded <- file <-
    overrides). Keys the recording lacks (older versions) keep today's defaults."""
    text = rec.setup.config_toml
    if text is None:
        raise InputError(f"{path}: the recording has no effective config (setup/config)")
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{path}: the recorded config is not valid TOML ({e})") from None
    table.pop("recording", None)   # how the run was recorded is not how the replay records
    where = f"{path} (recorded config)"
    return load_config(recorded=(where, table)), load_config(config_path, overrides, recorded=(where, table))


def tracker_seed(rec: Recording) -> int:
    """The tracker seed as `track` records it ({"tracker": s, "sim": ...}) or a plain int."""
    s = rec.setup.seed
    if isinstance(s, dict):
        s = s.get("tracker", 0)
    return int(s or 0)


def load_replay(path: str | Path, config_path: str | Path | None = None, overrides: Sequence[str] = (),
                fixed_generations: bool = False, allow_partial: bool = False) -> ReplaySetup:
    """Read a recording and rebuild rig, photo-model, config and seed for `replay`. Changed
    photo-model keys rebuild the model from the recorded photo, as does a recorded model that lacks
    a field (recorded before the field existed); changed photo-model and hue keys need a
    recording with full frames (`record.planes`)."""
    p = Path(path)
    rec = read_checked(p, allow_partial)
    rec_cfg, cfg = recorded_config(rec, p, config_path, overrides)
    rig = rec.setup.rig()
    if rig is None or rig.T_flange_left() is None:
        raise InputError(f"{p}: the recording has no rig with a hand-eye transform: nothing to replay")
    if rec.setup.model is None and rec.setup.photo_bgr is None:
        raise InputError(f"{p}: the recording has no photo-model and no photo: nothing to replay")
    if not rec.frames:
        raise InputError(f"{p}: the recording holds no frames")
    changed = _changed_frame_keys(rec_cfg, cfg)
    if changed and not rec.setup.full_frames:
        raise InputError(f"{p}: a {rec.setup.run.get('mode')} recording keeps the tracker's hue classes, not the "
                         f"frames: {', '.join(changed)} cannot change (record with recording.mode=\"full\")")
    if not rec.setup.full_frames and cfg.recording.mode == "full":
        raise InputError(f"{p}: a {rec.setup.run.get('mode')} recording has no full frames to write: "
                         "recording.mode cannot be \"full\" for its replay")
    model = rec.setup.model
    # a recording made before the photo-model gained a field (the reader leaves its model None) gets
    # the model rebuilt from its recorded photo, as changed photo-model keys do
    if model is None or cfg.photo_model != rec_cfg.photo_model:
        from photoservo.vision.photo_model import build_photo_model
        model = build_photo_model(rec.setup.photo_bgr, cfg.photo_model)
    budgeted = not rec_cfg.sim.lockstep
    same_n = cfg.tracker.generations_per_frame == rec_cfg.tracker.generations_per_frame
    return ReplaySetup(p, rec, rec_cfg, cfg, rig, model, rec.setup.photo_bgr, tracker_seed(rec),
                       recorded_generations=budgeted and same_n and not fixed_generations)


def _changed_frame_keys(a: Config, b: Config) -> list[str]:
    """The photo-model and hue keys (`planes.HUE_KEYS`) that differ between two configs."""
    from photoservo.record.planes import HUE_KEYS
    keys = [f"photo_model.{f.name}" for f in dataclasses.fields(a.photo_model)] + list(HUE_KEYS)

    def value(cfg: Config, key: str) -> Any:
        section, name = key.split(".")
        return getattr(getattr(cfg, section), name)
    return [k for k in keys if value(a, k) != value(b, k)]


# ------------------------------------------------------------------------------------------
# the replay


@dataclass(frozen=True)
class FrameResult:
    """The replayed tracker's answer for one recorded frame (numbers only, for comparisons)."""

    frame: int
    status: str
    found: bool
    fitness: float
    generations: int
    position_mm: tuple[float, ...] | None   # measured model position in the left camera
    alpha: float | None


@dataclass
class ReplayResult:
    setup: ReplaySetup
    out_path: Path | None         # the replay's recording (None: not kept, `record=False`)
    frames: list[FrameResult]
    commands: np.ndarray          # (N, 7) open-loop setpoint.dq at the logged control ticks
    seconds: float                # wall time of the replay (tracker + control + recording)
    comparison: Comparison | None = None
    events: list[tuple[float, str]] = field(default_factory=list)

    @property
    def fps(self) -> float:
        return len(self.frames) / self.seconds if self.seconds > 0 else float("nan")


def _frames_with_meta(setup: ReplaySetup) -> Iterator[tuple[Frame, Any]]:
    """The recorded frames (images streamed from the file) with their metadata, in order."""
    meta = {m.index: m for m in setup.recording.frames}
    for fr in iter_frames(setup.path):
        m = meta.get(fr.index)
        if m is None:
            continue
        if m.T_base_left is None:
            raise InputError(f"{setup.path}: frame {fr.index} has no camera pose (T_base_left): cannot replay")
        yield fr, m


def _processing_delays(rec: Recording) -> dict[int, float]:
    """frame -> seconds the recorded real-time run spent on it (timing/hue + timing/ga, logged
    at the frame's time): its track reached the control thread that much after delivery."""
    h, g = rec.timings.get("hue"), rec.timings.get("ga")
    if h is None or g is None or len(h.t) != len(g.t):
        return {}
    by_t = {float(t): 1e-3 * float(a[0] + b[0]) for t, a, b in zip(h.t, h.values, g.values)}
    return {m.index: by_t[m.t] for m in rec.frames if m.t in by_t}


def _available(m: Any, latency: float, busy: dict[int, float]) -> float:
    """When the control law may use frame m's track: capture + latency (+ the recorded
    processing time of a real-time run), as in the lockstep session."""
    t_l = (m.capture_times or (m.t,))[0]
    return t_l + latency + busy.get(m.index, 0.0)


class _CopiedVideo:
    """The replay's recorder, logging each frame's recorded video samples (set in `samples`)
    instead of encoding the frames it is given (a compact recording's frames are its grey
    planes, not the pictures)."""

    def __init__(self, recorder: Any) -> None:
        self.recorder, self.samples = recorder, None

    def __getattr__(self, name: str) -> Any:
        return getattr(self.recorder, name)

    def log_frame(self, *args: Any, **kwargs: Any) -> None:
        self.recorder.log_frame(*args, video=self.samples, **kwargs)


def _tracker_frame(fr: Frame, path: Path) -> tuple[np.ndarray, np.ndarray, Any]:
    """(left BGR, right BGR, fitness input or None) of a recorded frame: the full frames, or
    the compact planes (`record.planes.tracker_input`)."""
    if fr.left is not None and fr.right is not None:
        return fr.left, fr.right, None
    from photoservo.record.planes import tracker_input
    from photoservo.vision.fitness import StereoHue
    try:
        hue, left, right = tracker_input(fr.planes or {}, StereoHue)
    except KeyError as e:
        raise InputError(f"{path}: frame {fr.index} lacks the {e.args[0]} (recorded by an older "
                         "photoservo): it cannot be replayed") from None
    return left, right, hue


class _ReplayLoop:
    """One replay: the recorded frames through a fresh tracker (vision side) and the control law
    open loop on the recorded joint states (control side), both through the product loop's body
    (servo/session.py: vision_step, control_tick, log_tick)."""

    def __init__(self, setup: ReplaySetup, recorder: Any, progress: Callable[[int, int], None] | None) -> None:
        from photoservo.servo.scores import Scores
        from photoservo.servo.session import ControlLoop, controller_for
        from photoservo.vision.tracker import Tracker

        self.setup, self.cfg, self.rec, self.recorder, self.progress = setup, setup.cfg, setup.recording, recorder, progress
        self.tracker = Tracker.from_config(setup.model, setup.rig, self.cfg, seed=setup.seed, time_budget=False)
        self.control = ControlLoop(controller_for(self.cfg, setup.rig), None, Scores(settle_s=self.cfg.servo.settle_s))
        self.rec_gens = {e.frame: e.generations for e in self.rec.estimates}
        self.truth = {tr.frame: tr for tr in self.rec.truth}
        self.latency = self.cfg.sim.capture_latency_s
        self.busy = _processing_delays(self.rec) if not setup.recorded_cfg.sim.lockstep else {}
        self.frames = _frames_with_meta(setup)
        self.pending: tuple[Frame, Any] | None = next(self.frames, None)
        self.track = None
        self.results: list[FrameResult] = []
        self.commands: list[np.ndarray] = []

    def deliver(self, upto: float) -> None:
        """Every recorded frame whose track is available by `upto` (s) through the tracker."""
        from photoservo.servo.session import Frame as LoopFrame, vision_step

        while self.pending is not None and _available(self.pending[1], self.latency, self.busy) <= upto + 1e-9:
            fr, m = self.pending
            t_l, t_r = m.capture_times or (m.t, m.t)
            n_rec = self.rec_gens.get(fr.index)
            capped = (self.setup.recorded_generations and n_rec is not None
                      and 1 <= n_rec < self.cfg.tracker.generations_per_frame)   # (acquiring frames ignore it)
            left, right, hue = _tracker_frame(fr, self.setup.path)
            self.recorder.samples = None if self.rec.setup.full_frames else fr.video
            lf = LoopFrame(fr.index, t_l, t_r, _available(m, self.latency, self.busy), left, right, m.T_base_left)
            track = vision_step(lf, self.tracker, self.cfg, self.control.scores, self.recorder, None,
                                self.control.ctrl.events, n_rec if capped else None, hue=hue)
            tr = self.truth.get(fr.index)
            if tr is not None:
                self.recorder.log_truth(fr.index, t_l, tr.T_base_target,
                                        None if tr.size_mm is None else tuple(tr.size_mm))
            self.results.append(FrameResult(
                fr.index, track.status, bool(track.found), float(track.fitness), int(track.generations),
                None if track.t_left is None else tuple(float(x) for x in track.t_left),
                None if track.alpha_measured is None else float(track.alpha_measured)))
            if self.progress is not None:
                self.progress(len(self.results), len(self.rec.frames))
            self.track, self.pending = track, next(self.frames, None)

    def run(self) -> None:
        """Control ticks at the control rate over the recorded joint states (arm/q), frames
        delivered between them; then the frames after the last joint sample."""
        from photoservo.servo.session import ARM_LOG_EVERY, control_tick, log_tick

        q_series = self.rec.arm.get("q")
        if q_series is not None and len(q_series.t):
            arm = JointHistory.from_samples(q_series.t, q_series.values)
            dt = 1.0 / self.cfg.motion.rate_hz
            t_first, t_last = arm.span
            i0, i1 = math.ceil(t_first / dt - 1e-6), math.floor(t_last / dt + 1e-6)
            for i in range(i0, i1 + 1):
                now = i * dt
                self.deliver(now)
                q, dq = arm.at(now)
                tick = control_tick(self.control, now, now, q, dq, self.track)
                log_tick(self.recorder, tick, i - i0)
                if (i - i0) % ARM_LOG_EVERY == 0:
                    self.commands.append(np.array(tick.setpoint_dq))
        self.deliver(math.inf)   # frames after the last arm sample (or no arm series at all)
        c = self.control
        for t_e, text in c.ctrl.events[c.n_events:]:
            self.recorder.event(t_e, text)
        c.n_events = len(c.ctrl.events)


def replay(setup: ReplaySetup, out: str | Path | None = None, *, view: bool = False,
           progress: Callable[[int, int], None] | None = None, record: bool = True) -> ReplayResult:
    """Re-run the tracker on every recorded frame and the control law open loop on the recorded
    joint states (module docstring); write the new recording to `out` (None: the [recording]
    default path; `record=False`: a temporary file, deleted after the comparison) and compare
    it with the recorded run."""
    import tempfile

    from photoservo.record.recorder import Recorder
    from photoservo.vision.rig import dump_rig

    cfg, rec = setup.cfg, setup.recording
    tmp = None if record else tempfile.TemporaryDirectory(prefix="photoservo-replay-")
    if tmp is not None:
        out = Path(tmp.name) / "replay.rrd"
    recorder = _CopiedVideo(Recorder.from_config(cfg.recording, "replay", out, view=view))
    t_start = time.perf_counter()
    try:
        recorder.log_static_setup(dump_rig(setup.rig), setup.photo, setup.model, dump_config(cfg),
                                  rec.setup.seed)   # versions: this software, which replayed it
        recorder.event(rec.frames[0].t, f"replay of {setup.path.name}: {setup.generations_note}")
        loop = _ReplayLoop(setup, recorder, progress)
        loop.run()
    finally:
        recorder.close()
    seconds = time.perf_counter() - t_start
    try:
        result = ReplayResult(setup, recorder.path if record else None, loop.results,
                              np.array(loop.commands).reshape(-1, 7), seconds, events=list(loop.control.ctrl.events))
        result.comparison = compare_runs(rec, read_recording(recorder.path), "recorded", "replay")
    finally:
        if tmp is not None:
            tmp.cleanup()
    return result


# ------------------------------------------------------------------------------------------
# the same world, closed loop


@dataclass
class WorldFrom:
    """A simulated recording's world for `track --sim --world-from REC`."""

    path: Path
    recording: Recording
    cfg: Config           # recorded <- --config <- --set
    seed: int             # tracker seed (recorded unless given)
    duration_s: float     # the recorded run's length (from its arm samples)
    changed_sim_keys: list[str]


def world_from(path: str | Path, config_path: str | Path | None = None, overrides: Sequence[str] = (),
               seed: int | None = None, allow_partial: bool = False) -> WorldFrom:
    """Rebuild the simulated world of a recording: its effective config (the [sim] section:
    seed, target motion, camera timing) with --config/--set on top, and its tracker seed. A
    truncated recording is an InputError unless `allow_partial`."""
    p = Path(path)
    rec = _read(p, allow_partial)
    if not rec.truth:
        raise InputError(f"{p}: not a simulated recording (no ground truth): --world-from needs one")
    rec_cfg, cfg = recorded_config(rec, p, config_path, overrides)
    changed = [f.name for f in dataclasses.fields(cfg.sim)
               if getattr(cfg.sim, f.name) != getattr(rec_cfg.sim, f.name)]
    q = rec.arm.get("q")
    if q is not None and len(q.t) > 1:
        duration = float(q.t[-1] + np.median(np.diff(q.t)))
    else:
        duration = float(rec.frames[-1].t + 1.0 / rec_cfg.sim.camera_fps) if rec.frames else 0.0
    return WorldFrom(p, rec, cfg, tracker_seed(rec) if seed is None else seed, duration, changed)
