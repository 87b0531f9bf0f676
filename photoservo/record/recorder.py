"""Rerun recordings of a session (issues 6 and 13): every run inspectable, replayable and tunable.

The recorder listens on the side of the loop (frames -> tracker -> pose -> control -> arm): the
loop hands it what it already has and it writes ONE `.rrd` file (rerun-sdk 0.41, pinned <0.42:
`record.reader` reads files back with `rerun.chunk.RrdReader`). What goes where: `record.layout`.

API (one `Recorder` per run; thread-safe; no global rerun state — a `rr.RecordingStream`)::

    with Recorder.open(None, "track", mode="compact") as rec:
        rec.log_static_setup(rig_toml, photo_bgr, model, config_toml, seed)
        for ...:
            rec.log_frame(k, t, left_bgr, right_bgr, T_base_left=T, fitness_input=hue)
            rec.log_estimate(k, t, found=..., fitness=..., R=..., position_mm=..., alpha=...,
                             size_mm=..., projection=proj)
            rec.log_truth(k, t, T_base_target, size_mm)                # simulation only
            rec.log_desired(t, T_base_cam_desired)
            rec.log_arm(t, q, setpoint, command)        # rad, rad/s; control thread is fine
            rec.log_timings(t, {"capture": 1.2, "ga": 20.1})           # ms
            rec.event(t, "target lost")
    print(rec.path if rec.written else "nothing recorded")

Modes (`benchmarks/recording.py` measures each; 640x480 stereo at 30 fps):
  compact  (default) the tracker's input, losslessly (`record.planes`: hue classes + grey near
           the target, PNG) + a watch-only video (`record.video`): replays tracker / GA /
           estimator / servo keys exactly, ~1/30 of the full frames' size.
  full     every frame's pixels (rr.Image, compressed by rerun's LZ4 in its writer thread):
           the only mode whose replay may change photo-model and hue keys (`planes.HUE_KEYS`).
  preview  the video only: watched, NOT replayable (said in setup/WARNING, setup/run, an event
           and a Python warning).

One name: the file is the path given (or `default_path`), nothing else; `rerun PATH`,
`rerun rrd stats PATH` and `photoservo replay PATH` open it as printed. Rerun writes it as it
goes (its batcher every BATCH_S, the queued series every `drawing.SERIES_FLUSH_S`), so a hard
kill loses about a second; the file then lacks its footer, which the reader reports.
`close()` (also from `__exit__`, on Ctrl-C and exceptions) drains the encoders, flushes and
writes the footer (`rerun rrd verify` accepts the file).

No file for a run that never started: the stream buffers the setup in memory and the file is
opened at the first frame or arm sample (`written`); a start that fails before that leaves none.

Cost: a rerun log call costs ~0.1-0.2 ms of Python, so the time series are queued and pictures
drawn at the video's rate (`record.drawing`), the planes and video encoded on two worker threads
(`record.encoding`); the loop copies the frame and queues it."""

from __future__ import annotations

import json
import logging
import threading
import tomllib
import uuid
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal, Self

import numpy as np

from photoservo.errors import InputError
from photoservo.record import layout as L
from photoservo.record.layout import rr
from photoservo.record.drawing import Drawing, transform
from photoservo.record.encoding import VIDEO_LAG_S, FrameEncoding, Worker
from photoservo.record.files import default_path, rerun_cli, software_versions
from photoservo.geometry import make_pose

log = logging.getLogger(__name__)

Mode = Literal["compact", "full", "preview"]
MODES: tuple[str, ...] = ("compact", "full", "preview")
VideoCodec = Literal["av1", "h264", "none"]
SPAWN_WAIT_S = 5.0     # longest wait for a spawned viewer to listen
#: rerun's batcher writes a chunk per entity this often: each chunk carries its ~2 KB schema, so
#: longer saves space (benchmarks/recording.py); a hard kill loses at most about this much
BATCH_S = 1.0
#: frames of per-frame logging the loop may be ahead of the recorder's logging thread before it waits
DEFERRED_FRAMES = 16
PREVIEW_WARNING = ("PREVIEW RECORDING: the frames are only a lossy video. This recording is for "
                   "viewing only and CANNOT be replayed.")


@dataclass(frozen=True)
class RecordingParams:
    """[recording] config: how sessions are recorded."""

    mode: Literal["compact", "full", "preview"]  # what of the frames is kept (module docstring)
    video: Literal["av1", "h264", "none"]  # the watch-only video's codec (compact, preview)
    video_fps: float  # the watch-only video's frame rate (Hz): frames between are not encoded; 0 = every frame
    dir: str  # folder for default recording paths (logs/<timestamp>_<verb>.rrd)

    def validate(self, where: str) -> None:
        if self.mode == "preview" and self.video == "none":
            raise InputError(f"config key '{where}.video': \"none\" leaves a preview recording "
                             "nothing of the frames; choose av1 or h264")


class Recorder:
    """Writes one session to one `.rrd` file; see the module docstring.

    Every method takes the loop's monotonic time `t` (s) and, for per-frame data, the frame
    index. Methods may be called from several threads (e.g. the control thread for
    `log_arm`); each call sets its own time, so no rerun time state leaks between threads.
    """

    def __init__(self, path: Path, verb: str, mode: Mode, video: VideoCodec, view: bool,
                 connect_url: str | None, video_fps: float = 0.0) -> None:
        if mode not in MODES:
            raise InputError(f"recording mode '{mode}': expected one of {', '.join(MODES)}")
        from photoservo.record.video import CODECS
        if video not in CODECS:
            raise InputError(f"recording video '{video}': expected one of {', '.join(CODECS)}")
        if mode == "preview" and video == "none":
            raise InputError("a preview recording is its video: the video codec cannot be 'none'")
        if not (np.isfinite(video_fps) and video_fps >= 0):
            raise InputError(f"recording video_fps {video_fps}: expected a rate >= 0 Hz (0 = every frame)")
        self.path = Path(path)
        self.verb, self.mode, self.video = verb, mode, video
        self.replayable = mode != "preview"
        self.recording_id = str(uuid.uuid4())
        self._lock = threading.RLock()
        self._rec = rr.RecordingStream(L.APPLICATION_ID, recording_id=self.recording_id,
                                       batcher_config=rr.ChunkBatcherConfig(flush_tick=BATCH_S))
        self._grpc_url = (connect_url or self._spawn_viewer()) if (view or connect_url) else None
        self._started = self._closed = False
        self._last_t = 0.0
        self.frames_logged = 0
        self._deferred = Worker("recorder-log", DEFERRED_FRAMES)   # the loop's logging (module docstring)
        self.encoding = None if mode == "full" else FrameEncoding(self, mode == "compact", video, video_fps)
        self.draw = Drawing(self, video_fps if mode != "full" else 0.0)
        self._log_static("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP)
        self.draw.point_styles()
        for entity in L.E_ARM:
            self._log_static(entity, rr.SeriesLines(names=list(L.JOINT_NAMES)))
        self._log_static(L.E_RUN, rr.TextDocument(json.dumps(self._run_info(None, None), indent=1)))
        if not self.replayable:
            warnings.warn(f"{self.path}: {PREVIEW_WARNING}", stacklevel=3)
            self._log_static(L.E_WARNING, rr.TextDocument(PREVIEW_WARNING))
        self._preview_event_due = not self.replayable   # logged at the first frame's time

    # --- opening and closing -------------------------------------------------------------

    @classmethod
    def open(cls, path: str | Path | None, verb: str, *, mode: Mode = "compact",
             video: VideoCodec = "av1", view: bool = False, connect_url: str | None = None,
             logs_dir: str | Path = "logs", video_fps: float = 0.0) -> Recorder:
        """Start a recording (the file itself appears at the first frame or arm sample).

        path: the `.rrd` to write (must not exist); None -> `default_path(verb, logs_dir)`.
        mode: 'compact', 'full' or 'preview' (module docstring); video: its codec; video_fps:
        the video's frame rate (Hz; 0 = every frame logged).
        view: spawn a viewer and stream to it while writing the file (returns at once).
        connect_url: stream to a running viewer (`rerun+http://host:9876/proxy`) as well.
        """
        p = Path(path) if path is not None else default_path(verb, logs_dir)
        if p.suffix != ".rrd":
            raise InputError(f"{p}: a recording path must end in .rrd")
        if p.exists():
            raise InputError(f"{p}: exists already; choose another recording path or remove it")
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise InputError(f"{p.parent}: cannot create the recording folder ({e.strerror})") from None
        return cls(p, verb, mode, video, view, connect_url, video_fps)

    @classmethod
    def from_config(cls, params: RecordingParams, verb: str, path: str | Path | None = None, *,
                    view: bool = False, connect_url: str | None = None) -> Recorder:
        """`open` with the [recording] config (mode, video, dir); `path` overrides the default
        `<dir>/<UTC time>_<verb>.rrd`."""
        return cls.open(path, verb, mode=params.mode, video=params.video, view=view,
                        connect_url=connect_url, logs_dir=params.dir, video_fps=params.video_fps)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc is not None and not self._closed:
            try:
                self.event(self._last_t, f"session ended by {exc_type.__name__}: {exc}", level="ERROR")
            except Exception:  # never mask the original exception
                log.exception("could not log the closing event")
        self.close()

    @property
    def written(self) -> bool:
        """Whether the file exists: the session produced a frame or an arm sample."""
        return self._started

    def close(self) -> None:
        """Drain the workers and encoders, flush, write the footer and disconnect. Idempotent.
        A recording that never started writes nothing."""
        if self._closed:
            return
        self._closed = True
        try:
            self._deferred.stop()
            if self.encoding is not None:
                self.encoding.close()
        finally:
            with self._lock:
                try:
                    if self._preview_event_due and self._started:
                        self._log(L.E_EVENTS, self._last_t, None, rr.TextLog(PREVIEW_WARNING, level="WARN"))
                    dropped = 0 if self.encoding is None else self.encoding.video_dropped
                    if dropped and self._started:
                        self._log(L.E_EVENTS, self._last_t, None, rr.TextLog(
                            f"{dropped} frames left out of the watch-only video: its encoder was "
                            f"more than {VIDEO_LAG_S:g} s behind (short of CPU); the planes kept every frame",
                            level="WARN"))
                    self.draw.close()
                finally:
                    if self._started:
                        try:
                            self._rec.flush(timeout_sec=10.0)
                        except Exception as e:  # noqa: BLE001 - an unreachable viewer must not cost the file
                            log.warning("recording flush: %s", e)
                    self._rec.disconnect()
        self._raise_worker_error()

    def _raise_worker_error(self) -> None:
        error = self._deferred.error or (None if self.encoding is None else self.encoding.error)
        if error is not None:
            raise RuntimeError(f"recording to {self.path} failed: {error}") from error

    def _spawn_viewer(self, port: int = 9876) -> str | None:
        """Start a viewer process and return its gRPC URL (None if it cannot start: the
        recording then goes to the file only). We wait at most SPAWN_WAIT_S for it to listen,
        so a viewer that cannot come up (no display) never holds the session."""
        failed: list[BaseException] = []
        cli = rerun_cli()

        def spawn() -> None:
            try:
                rr.spawn(port=port, connect=False, hide_welcome_screen=True, recording=self._rec,
                         executable_path=str(cli) if cli.is_file() else None)
            except Exception as e:  # noqa: BLE001 - reported below, the file still gets written
                failed.append(e)

        th = threading.Thread(target=spawn, name="recorder-spawn-viewer", daemon=True)
        th.start()
        th.join(SPAWN_WAIT_S)
        if failed:
            warnings.warn(f"viewer could not be started ({failed[0]}); recording to {self.path} only",
                          stacklevel=4)
            return None
        return f"rerun+http://127.0.0.1:{port}/proxy"

    def _start(self) -> None:
        """Open the file (and the viewer stream): what was logged so far, buffered by the
        stream, goes into it first. The blueprint goes with the file."""
        with self._lock:
            if self._started:
                return
            if self.path.exists():   # appeared since `open`: never overwrite a recording
                raise InputError(f"{self.path}: exists already; choose another recording path or remove it")
            bp = L.blueprint()
            if self._grpc_url:
                self._rec.set_sinks(rr.GrpcSink(self._grpc_url), rr.FileSink(str(self.path)),
                                    default_blueprint=bp)
            else:
                self._rec.save(self.path, default_blueprint=bp)
            self._started = True

    # --- low-level logging ----------------------------------------------------------------

    def _check(self) -> None:
        self._raise_worker_error()
        if self._closed:
            raise RuntimeError(f"recording to {self.path} is closed")

    def flush(self) -> None:
        """Wait until everything logged so far has gone to the stream, then flush the stream
        (the file has it; a hard kill after this loses none of it)."""
        self._check()
        self._deferred.queue.join()
        self._raise_worker_error()
        with self._lock:
            self._rec.flush()

    def _defer(self, fn: Any, *args: Any) -> None:
        """Run fn(*args) on the recorder's logging thread, in call order: a rerun call costs
        the calling thread its GIL at every entry and exit, which beside the control-link and
        encoding threads cost the session loop 20-50 ms a frame here (measured in `track`)."""
        self._deferred.queue.put(lambda: fn(*args))

    def _log_static(self, entity: str, *parts: Any) -> None:
        with self._lock:
            self._rec.log(entity, *parts, static=True)

    def _log(self, entity: str, t: float, frame: int | None, *parts: Any) -> None:
        with self._lock:
            self._rec.reset_time()
            if frame is not None:
                self._rec.set_time("frame", sequence=int(frame))
            self._rec.set_time("time", duration=float(t))
            self._rec.log(entity, *parts)

    def _run_info(self, seed: Any, versions: Mapping[str, str] | None) -> dict:
        from photoservo.record import planes
        return {"format": L.FORMAT_VERSION, "verb": self.verb, "mode": self.mode,
                "video": self.video if self.mode != "full" else None,
                "video_fps": self.encoding.video_fps if self.encoding is not None else None,
                "replayable": self.replayable, "full_frames": self.mode == "full",
                "seed": dict(seed) if isinstance(seed, Mapping) else seed,
                "versions": dict(versions or software_versions()),
                "recording_id": self.recording_id,
                "started_utc": datetime.now(UTC).isoformat(timespec="seconds"),
                "planes": ({"grey_radius_px": planes.GREY_RADIUS_PX,
                            "fixed_keys": ["photo_model.*", *planes.HUE_KEYS]}
                           if self.mode == "compact" else None),
                "layouts": {L.E_DATA_FRAME: L.FRAME_LAYOUT, L.E_DATA_EST: L.EST_LAYOUT,
                            L.E_DATA_TRUTH: L.TRUTH_LAYOUT}}

    # --- static setup ---------------------------------------------------------------------

    def log_static_setup(self, rig_toml_text: str | None, photo_bgr: np.ndarray | None = None,
                         model: Any = None, config_toml_text: str | None = None,
                         seed: int | Mapping[str, int] | None = None,
                         versions: Mapping[str, str] | None = None) -> None:
        """Everything replay needs besides the frames, logged static: the rig (TOML text, and
        the Pinholes/stereo transform drawn from it), the photo (PNG) and its PhotoModel (every
        array, bit-exact), the effective config TOML, the seed (one int, or several by name,
        e.g. {"tracker": 1, "sim": 2}) and the software versions (default:
        `software_versions()`). Any part may be None (e.g. for `move`). The model and the
        config's [fitness] section decide the compact mode's hue classes."""
        self._check()
        self._log_static(L.E_RUN, rr.TextDocument(json.dumps(self._run_info(seed, versions), indent=1)))
        if rig_toml_text is not None:
            from photoservo.vision.rig import parse_rig
            rig = parse_rig(tomllib.loads(rig_toml_text), "recorded rig")
            self._log_static(L.E_RIG_TOML, rr.TextDocument(rig_toml_text))
            self.draw.rig(rig)
        if config_toml_text is not None:
            self._log_static(L.E_CONFIG, rr.TextDocument(config_toml_text))
            if self.encoding is not None:
                cfg = _recorded_config(config_toml_text)
                self.encoding.fitness = None if cfg is None else cfg.fitness
                self.encoding.layout_share = 0.0 if cfg is None else cfg.estimator.layout_share
        if photo_bgr is not None:
            self.draw.photo(photo_bgr)
        if model is not None:
            self.draw.model(model)
            if self.encoding is not None:
                self.encoding.set_model(model, self.encoding.fitness)

    # --- per-frame data -------------------------------------------------------------------

    def log_frame(self, frame: int, t: float, left_bgr: np.ndarray, right_bgr: np.ndarray, *,
                  T_base_left: np.ndarray | None = None, capture_times: tuple[float, float] | None = None,
                  fitness_input: Any = None, video: Mapping[str, list] | None = None) -> None:
        """One stereo frame (BGR uint8) at loop time t (s), and where the left camera was
        (T_base_left, 4x4 mm, the flange pose at capture times the hand-eye).

        fitness_input: what the tracker scored this frame on (`vision.fitness.StereoHue`),
            recorded in compact mode (computed here from the frames and the recorded [fitness]
            floors when not given). It must not change after this call.
        video: already encoded samples per side (`video.Sample`, e.g. copied by a replay from
            its recording) logged instead of encoding the frames."""
        self._check()
        self._start()
        self._last_t = t
        left, right = _bgr(left_bgr).copy(), _bgr(right_bgr).copy()
        T = None if T_base_left is None else np.array(T_base_left, dtype=np.float64)
        if fitness_input is not None and self.mode == "compact":
            from photoservo.record.encoding import copied
            fitness_input = copied(fitness_input)
        self._defer(self._frame_now, frame, t, left, right, T, capture_times, fitness_input, video)
        self.frames_logged += 1

    def _frame_now(self, frame: int, t: float, left: np.ndarray, right: np.ndarray, T_base_left: np.ndarray | None,
                   capture_times: tuple[float, float] | None, fitness_input: Any, video: Mapping[str, list] | None) -> None:
        """`log_frame`'s logging, on the recorder's logging thread (the frames are copies)."""
        if self._preview_event_due:
            self._preview_event_due = False
            self._log(L.E_EVENTS, t, None, rr.TextLog(PREVIEW_WARNING, level="WARN"))
        self.draw.tick(t)
        if T_base_left is not None and self.draw.due(frame, t):
            self._log("world/rig", t, frame, transform(T_base_left))
        self._log(L.E_DATA_FRAME, t, frame, rr.AnyValues(values=L.pack(L.FRAME_LAYOUT, {
            "capture_times": capture_times, "T_base_left": T_base_left})))
        if self.mode == "full":
            for side, img in (("left", left), ("right", right)):
                self._log(L.E_IMAGE[side], t, frame, rr.Image(img, color_model="BGR"))
        else:
            self.encoding.queue(frame, t, left, right, fitness_input, video)

    def log_estimate_of(self, frame: int, t: float, estimate: Any, *,
                        T_base_left: np.ndarray | None = None, projection: Any = None) -> None:
        """`log_estimate` from a `vision.estimator.Estimate` (or anything with the DESIGN.md
        estimate fields: found, position_mm, rotation, alpha_px_per_mm, size_mm, fitness,
        generations)."""
        e = estimate
        self.log_estimate(frame, t, found=bool(e.found), fitness=e.fitness, R=e.rotation,
                          position_mm=e.position_mm, alpha=e.alpha_px_per_mm, size_mm=e.size_mm,
                          generations=int(e.generations), T_base_left=T_base_left,
                          projection=projection)

    def log_estimate(self, frame: int, t: float, *, found: bool, fitness: float | None,
                     R: np.ndarray | None = None, position_mm: np.ndarray | None = None,
                     alpha: float | None = None, size_mm: tuple[float, float] | None = None,
                     generations: int = 0, T_base_left: np.ndarray | None = None,
                     projection: Any = None) -> None:
        """The tracker's best individual for a frame: pose "model in left camera"
        (X_left = R X_model + position_mm), alpha (px/mm), size_mm, fitness, found.
        projection: its projected points (`vision.fitness.ModelProjection`), drawn on the
        images; when not given they are projected from R, position_mm and alpha with the
        photo-model and rig of `log_static_setup`, on the frames drawn only. T_base_left places
        the model in the base frame (3-D view, truth)."""
        self._check()
        self._start()
        self._last_t = t
        own = (lambda a: None if a is None else np.array(a, dtype=np.float64))
        self._defer(self._estimate_now, frame, t, found, fitness, own(R), own(position_mm), alpha, size_mm,
                    generations, own(T_base_left), projection)

    def _estimate_now(self, frame: int, t: float, found: bool, fitness: float | None, R: np.ndarray | None,
                      position_mm: np.ndarray | None, alpha: float | None, size_mm: tuple[float, float] | None,
                      generations: int, T_base_left: np.ndarray | None, projection: Any) -> None:
        """`log_estimate`'s logging, on the recorder's logging thread (the arrays are copies)."""
        if fitness is not None:
            self.draw.queue_scalar("plots/fitness", t, frame, float(fitness))
        self.draw.queue_scalar("plots/found", t, frame, 1.0 if found else 0.0)
        posed = found and R is not None and position_mm is not None
        if posed:  # the pictures only at the video's rate (`Drawing.due`)
            if alpha is not None:
                self.draw.queue_scalar("plots/alpha", t, frame, float(alpha))
            T_model = make_pose(R, position_mm)
            T_base_model = T_model if T_base_left is None else T_base_left @ T_model
            self.draw.box("world/target/estimate", t, frame, T_base_model, size_mm, [255, 140, 0])
        elif self.draw.due(frame, t):
            self._log("world/target/estimate", t, frame, rr.Clear(recursive=False))
        self.draw.projection(t, frame, found, projection,
                             (R, position_mm, alpha) if posed and alpha is not None else None)
        self._log(L.E_DATA_EST, t, frame, rr.AnyValues(values=L.pack(L.EST_LAYOUT, {
            "found": float(bool(found)), "fitness": fitness, "generations": generations,
            "alpha": alpha if posed else None, "rotation": R if posed else None,
            "position_mm": position_mm if posed else None, "size_mm": size_mm if posed else None,
            "T_base_left": T_base_left})))

    def log_truth(self, frame: int, t: float, T_base_target: np.ndarray,
                  size_mm: tuple[float, float] | None = None) -> None:
        """Simulation ground truth: the target's model frame in the base frame (4x4, mm)."""
        self._check()
        self._start()
        self._defer(self._truth_now, frame, t, np.array(T_base_target, dtype=np.float64), size_mm)

    def _truth_now(self, frame: int, t: float, T: np.ndarray, size_mm: tuple[float, float] | None) -> None:
        self.draw.box("world/target/truth", t, frame, T, size_mm, [0, 200, 255])
        self._log(L.E_DATA_TRUTH, t, frame, rr.AnyValues(values=L.pack(L.TRUTH_LAYOUT, {
            "T_base_target": T, "size_mm": size_mm})))

    def log_desired(self, t: float, T_base_cam_desired: np.ndarray, frame: int | None = None) -> None:
        """The desired (left) camera pose of the servo law, in the base frame (4x4, mm)."""
        self._check()
        self._start()
        self._log("world/target/desired", t, frame, transform(T_base_cam_desired),
                  rr.TransformAxes3D(axis_length=60.0))

    def log_arm(self, t: float, q: np.ndarray, setpoint: np.ndarray | None = None,
                command: np.ndarray | None = None) -> None:
        """Joint state q (rad), the motion setpoint (rad) and the velocity command sent
        (rad/s), at time t; recorded in degrees (`layout.E_ARM`), read back in rad. Cheap
        enough for the control thread: the sample is only queued (`drawing.Drawing`)."""
        self._check()
        self._start()
        self.draw.queue_arm(t, q, setpoint, command, self._last_t)

    def log_timings(self, t: float, timings_ms: Mapping[str, float], frame: int | None = None) -> None:
        """Per-stage durations of one loop iteration (ms), as `timing/<stage>_ms` (queued)."""
        self._check()
        self._start()
        for stage, ms in timings_ms.items():
            self.draw.queue_scalar(f"timing/{stage}_ms", t, frame, float(ms))

    @property
    def last_t(self) -> float:
        """Session time (s) of the newest frame or estimate logged: where a closing event goes."""
        return self._last_t

    def event(self, t: float, text: str, level: str = "INFO") -> None:
        """A line in the `events` text log (level: TRACE DEBUG INFO WARN ERROR CRITICAL).
        Events alone do not start the file: one logged before the session is kept with it."""
        self._check()
        self._log(L.E_EVENTS, t, None, rr.TextLog(text, level=level))


def _bgr(img: np.ndarray) -> np.ndarray:
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"frames must be (H, W, 3) uint8 BGR, got {img.shape} {img.dtype}")
    return np.asarray(img)


def _recorded_config(config_toml_text: str) -> Any:
    """The recorded effective config (defaults for missing keys), or None when it is not a
    valid photoservo config."""
    from photoservo.config import load_config
    try:
        return load_config(recorded=("recorded config", tomllib.loads(config_toml_text)))
    except (InputError, tomllib.TOMLDecodeError):
        return None
