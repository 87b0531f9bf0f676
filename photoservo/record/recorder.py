"""Rerun recordings of a session (issue 6): every run inspectable, replayable and tunable.

The recorder listens on the side of the loop (frames -> estimator -> pose -> control -> arm):
the loop hands it what it already has and it writes a `.rrd` file (rerun-sdk 0.41, pinned <0.42:
`photoservo.record.reader` reads files back with `rerun.chunk.RrdReader`).

API (one `Recorder` per run; thread-safe; no global rerun state — a `rr.RecordingStream`)::

    with Recorder.open(None, "track", mode="lossless", segment_s=60.0) as rec:
        rec.log_static_setup(rig_toml, photo_bgr, model, config_toml, seed)
        for ...:
            rec.log_frame(k, t, left_bgr, right_bgr, T_base_left=T)    # t: loop clock (s)
            rec.log_estimate(k, t, found=..., fitness=..., R=..., position_mm=..., alpha=...,
                             size_mm=..., projection=proj)
            rec.log_truth(k, t, T_base_target, size_mm)                # simulation only
            rec.log_desired(t, T_base_cam_desired)
            rec.log_arm(t, q, setpoint, command)                       # control thread is fine
            rec.log_timings(t, {"capture": 1.2, "ga": 20.1})           # ms
            rec.event(t, "target lost")
    # leaving the block (normally, by an exception or by Ctrl-C) flushes and finalises the file

Entity tree (mm, rad; `world` is the PA-10 base frame, z up)::

    world                      ViewCoordinates RIGHT_HAND_Z_UP (static)
    world/arm/link0..7         Transform3D T_base_link_i from forward kinematics + axes
    world/arm/skeleton         LineStrips3D through the link origins
    world/rig                  Transform3D T_base_left (the left camera; per frame, when known)
    world/rig/left             Pinhole K, camera_xyz RDF (X right, Y down, Z forward) (static)
    world/rig/left/image       the left frame (raw / PNG / JPEG, see modes)
    world/rig                  AnnotationContext: class 0 inner (green), 1 outer (magenta)
    world/rig/left/model       Points2D: the best model's projected inner and outer points
    world/rig/right            Transform3D X_right = R X_left + T (static) + Pinhole
    world/rig/right/...        as left
    world/target/estimate      Transform3D T_base_model + axes + Boxes3D (size_mm, flat)
    world/target/truth         the same for the simulator's ground truth
    world/target/desired       Transform3D T_base_cam_desired + axes
    world/flange/path          LineStrips3D, the flange's last `PATH_S` seconds, at 2 Hz
    plots/fitness|alpha|found  Scalars
    timing/<stage>_ms          Scalars
    arm/q|setpoint|command     Scalars, 7 named series (S1..W2) per entity (not 21 entities)
    events                     TextLog
    data/frame|estimate|truth  AnyValues `values`: the exact float64 numbers replay reads
                               back, one vector per row laid out by FRAME/EST/TRUTH_LAYOUT
    setup/run                  TextDocument JSON: verb, mode, replayable, seed, versions, ...
    setup/rig|config           TextDocument: the rig TOML, the effective config TOML
    setup/photo_model          AnyValues npz: the PhotoModel arrays, bit-exact
    setup/photo_model/photo    the photo (PNG) with the inner/outer points on it
    setup/WARNING              (preview mode only) "cannot be replayed"

The frames are logged ONCE, under the cameras' Pinholes, so the 3-D view shows them in the
frustums and the 2-D views (origin `world/rig/left`) show them with the projected points; a
second copy at `images/left` would double the file (see the benchmark for MB per minute).

Timelines: `frame` (sequence: the loop's frame index) and `time` (duration, seconds on the
loop's monotonic clock). Arm and event logs carry `time` only.

Cost: every rerun log call costs ~0.1-0.2 ms of Python, so the time series (plots/, timing/,
arm/) are queued and written as column chunks every SERIES_FLUSH_S (the live view lags by that
much), the arm is redrawn at most every ARM_DRAW_PERIOD_S, and a frame with its estimate is
about 8 log calls. `log_arm` only queues, so a control thread may call it.

Modes (chosen from `benchmarks/recording.py`, 640x480 stereo at 30 fps, on this 2-core
machine while loaded: CPU ms per stereo frame, whole process / MB per minute, clean synthetic
frames .. with 2.5 DN sensor noise):
  lossless  (default) the pixels as an rr.Image, compressed by rerun's own LZ4 chunk
            compression in its writer thread: bit-exact, replayable; ~8-13 ms CPU per frame,
            1650..3300 MB/min. The only lossless encoding that keeps up with 30 fps here.
  png       PNG (zlib level 1, Huffman-only, SUB filter) on a worker thread (cv2 releases the
            GIL): bit-exact, replayable, 1200..1800 MB/min (~30% less) but ~32-38 ms CPU per
            frame — a whole core at 30 fps, so for slow loops or offline re-recording.
  preview   JPEG q90 on the worker thread: 160..200 MB/min, ~5 ms, but LOSSY — hue changes, so
            replay refuses it; said in `setup/WARNING`, in `setup/run` ("replayable": false),
            as an event and as a Python warning. For long sessions that are only watched.

Nothing lost: `close()` (also from `__exit__` and on Ctrl-C/exceptions) drains the encoder,
flushes and disconnects, which writes the RRD footer (`rerun rrd verify` accepts the file).
Against a hard kill, `segment_s > 0` writes consecutive files `<stem>.seg0001.rrd`,
`<stem>.seg0002.rrd`, ... beside `<stem>.rrd` (which itself is then not written); a new one
starts at the first frame `segment_s` seconds after the segment's first frame. A segment is
written as `<stem>.segNNNN.partial.rrd` and renamed when rerun has written its footer, so every
`.segNNNN.rrd` is complete and verifies; after a kill only the `.partial.rrd` tail is cut short.
Each segment is a complete recording with the static setup (and blueprint) repeated, all with
the same recording id, so the viewer opens them together as one recording, and
`reader.read_recording(<stem>.rrd)` reads them as one (the partial tail as far as it goes).
"""

from __future__ import annotations

import dataclasses
import glob
import importlib
import io
import json
import logging
import math
import platform
import queue
import subprocess
import sys
import threading
import time
import uuid
import warnings
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal, Self

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.geometry import make_pose
from photoservo.robot.pa10 import JOINT_NAMES, fk_frames


class _LazyModule:
    """A module imported on first attribute access. `import rerun` takes 1-2 s here, and
    servo/config.py imports this module for `RecordingParams`, which every verb loads."""

    def __init__(self, name: str) -> None:
        self._name = name

    def __getattr__(self, attr: str) -> Any:
        value = getattr(importlib.import_module(self._name), attr)
        setattr(self, attr, value)   # later look-ups are plain attribute hits
        return value


rr: Any = _LazyModule("rerun")
rrb: Any = _LazyModule("rerun.blueprint")
pa: Any = _LazyModule("pyarrow")

log = logging.getLogger(__name__)

APPLICATION_ID = "photoservo"
FORMAT_VERSION = 1
Mode = Literal["lossless", "png", "preview"]
MODES: tuple[str, ...] = ("lossless", "png", "preview")

#: PNG parameters of the png mode: level 1 + Huffman-only + SUB filter was the cheapest of the
#: zlib settings tried (about half the CPU of the default filters at ~5% larger files).
PNG_PARAMS = [cv2.IMWRITE_PNG_COMPRESSION, 1,
              cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY,
              cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_SUB]
JPEG_QUALITY = 90
PATH_S = 10.0          # seconds of flange path kept in `world/flange/path`
PATH_PERIOD_S = 0.5    # how often the path strip is re-logged
SPAWN_WAIT_S = 5.0     # longest wait for a spawned viewer to listen
SERIES_FLUSH_S = 0.5   # queued time series (plots, timings, arm) are written this often
ARM_BATCH = 750        # ...or, when no frames come (move), at this many queued samples
ARM_DRAW_PERIOD_S = 0.1   # the arm is redrawn at most this often
PREVIEW_WARNING = ("PREVIEW RECORDING: frames are JPEG (lossy, hue changes). This recording "
                   "is for viewing only and CANNOT be replayed.")

# entity paths (reader readss the same constants)
E_RUN, E_RIG_TOML, E_CONFIG, E_WARNING = "setup/run", "setup/rig", "setup/config", "setup/WARNING"
E_MODEL, E_PHOTO = "setup/photo_model", "setup/photo_model/photo"
E_CAM = {"left": "world/rig/left", "right": "world/rig/right"}
E_IMAGE = {s: f"{p}/image" for s, p in E_CAM.items()}
E_DATA_FRAME, E_DATA_EST, E_DATA_TRUTH = "data/frame", "data/estimate", "data/truth"
E_EVENTS = "events"


@dataclass(frozen=True)
class RecordingParams:
    """[recording] config: how sessions are recorded."""

    mode: Literal["lossless", "png", "preview"]  # frame encoding, see the module docstring
    segment_s: float  # length of one segment file (s); 0 = one file (no hard-kill protection)
    dir: str  # folder for default recording paths (logs/<timestamp>_<verb>.rrd)

    def validate(self, where: str) -> None:
        if not self.segment_s >= 0 or not math.isfinite(self.segment_s):
            raise InputError(f"config key '{where}.segment_s': must be >= 0 s, got {self.segment_s}")


def default_path(verb: str, logs_dir: str | Path = "logs", now: datetime | None = None) -> Path:
    """`logs/<UTC timestamp>_<verb>.rrd`, e.g. logs/20261122T043700Z_track.rrd."""
    now = now or datetime.now(UTC)
    return Path(logs_dir) / f"{now.strftime('%Y%m%dT%H%M%SZ')}_{verb}.rrd"


def segment_path(path: str | Path, index: int, partial: bool = False) -> Path:
    """Path of segment `index` (1-based) of a recording whose base path is `path`; while it
    is being written it is `<stem>.segNNNN.partial.rrd` (renamed when finished)."""
    p = Path(path)
    return p.with_name(f"{p.stem}.seg{index:04d}{'.partial' if partial else ''}{p.suffix or '.rrd'}")


def rerun_cli() -> Path:
    """The `rerun` executable the rerun-sdk wheel installs beside this Python."""
    return Path(sys.executable).parent / "rerun"


def verify_rrd(path: str | Path, timeout_s: float = 120.0) -> tuple[bool, str]:
    """Run `rerun rrd verify PATH` (footer check on): (passed, the CLI's last output line)."""
    r = subprocess.run([str(rerun_cli()), "rrd", "verify", str(path)], check=False,
                       capture_output=True, text=True, timeout=timeout_s)
    lines = [s for s in (r.stdout + r.stderr).splitlines() if s.strip()]
    return r.returncode == 0, (lines[-1] if lines else "")


def software_versions() -> dict[str, str]:
    """Versions that decide whether a replay can reproduce a run."""
    from photoservo import __version__
    return {"photoservo": __version__, "python": platform.python_version(),
            "numpy": np.__version__, "opencv": cv2.__version__, "rerun": rr.__version__}


def blueprint() -> rrb.Blueprint:
    """The viewer layout, built in one place: scene and events left; both images with the
    projected points, then the plots, right; setup in a tab."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(origin="world", name="scene (base frame, mm)"),
                rrb.TextLogView(origin=E_EVENTS, name="events"),
                row_shares=[3, 1],
            ),
            rrb.Vertical(
                rrb.Horizontal(
                    rrb.Spatial2DView(origin=E_CAM["left"], name="left"),
                    rrb.Spatial2DView(origin=E_CAM["right"], name="right"),
                ),
                rrb.Tabs(
                    rrb.TimeSeriesView(origin="plots", name="fitness / alpha / found"),
                    rrb.TimeSeriesView(origin="timing", name="timings (ms)"),
                    rrb.TimeSeriesView(origin="arm", name="joints (rad)"),
                    rrb.Spatial2DView(origin=E_MODEL, name="photo-model"),
                    rrb.TextDocumentView(origin="setup", name="setup"),
                ),
            ),
            column_shares=[1, 1],
        ),
        collapse_panels=False,
    )


# ------------------------------------------------------------------------------------------
# encoding


def encode_frame(bgr: np.ndarray, mode: str) -> Any:
    """One camera frame (H, W, 3) uint8 BGR as the rerun archetype of `mode`."""
    if bgr.dtype != np.uint8 or bgr.ndim != 3 or bgr.shape[2] != 3:
        raise ValueError(f"frames must be (H, W, 3) uint8 BGR, got {bgr.shape} {bgr.dtype}")
    if mode == "lossless":
        return rr.Image(bgr, color_model="BGR")
    ext, params, media = ((".png", PNG_PARAMS, "image/png") if mode == "png"
                          else (".jpg", [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY], "image/jpeg"))
    ok, buf = cv2.imencode(ext, bgr, params)
    if not ok:
        raise RuntimeError(f"cannot encode a frame as {ext}")
    return rr.EncodedImage(contents=buf.tobytes(), media_type=media)


#: Per-frame numbers replay reads back exactly, one float64 vector per row (NaN = absent):
#: one AnyValues component instead of one per field (each costs ~0.2 ms of Python in rerun).
FRAME_LAYOUT = (("capture_times", 2), ("T_base_left", 16))
EST_LAYOUT = (("found", 1), ("fitness", 1), ("generations", 1), ("alpha", 1), ("rotation", 9),
              ("position_mm", 3), ("size_mm", 2), ("T_base_left", 16))
TRUTH_LAYOUT = (("T_base_target", 16), ("size_mm", 2))


def pack(layout: tuple[tuple[str, int], ...], values: Mapping[str, Any]) -> np.ndarray:
    """`values` laid out in one float64 vector by `layout` ((name, length), ...); a missing
    or None value becomes NaNs."""
    parts = []
    for name, n in layout:
        v = values.get(name)
        parts.append(np.full(n, np.nan) if v is None else np.asarray(v, dtype=np.float64).reshape(n))
    return np.concatenate(parts)


def unpack(layout: tuple[tuple[str, int], ...], vec: np.ndarray) -> dict[str, np.ndarray | None]:
    """Inverse of `pack`: name -> its values, or None when they were absent."""
    out: dict[str, np.ndarray | None] = {}
    i = 0
    for name, n in layout:
        part = np.asarray(vec[i:i + n], dtype=np.float64)
        out[name] = None if np.isnan(part).all() else part
        i += n
    return out


def pack_arrays(obj: Any) -> bytes:
    """A dataclass of arrays / numbers / tuples as npz bytes (bit-exact, self-describing)."""
    arrays = {f.name: np.asarray(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def _bytes_value(data: bytes) -> pa.Array:
    return pa.array([data], type=pa.binary())


def _transform(T: np.ndarray) -> rr.Transform3D:
    """A pose T_parent_child (4x4, mm) as a rerun transform (child in parent)."""
    T = np.asarray(T, dtype=np.float64)
    return rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3])


# ------------------------------------------------------------------------------------------
# the recorder


class Recorder:
    """Writes one session to a `.rrd` file (or segment files); see the module docstring.

    Every method takes the loop's monotonic time `t` (s) and, for per-frame data, the frame
    index. Methods may be called from several threads (e.g. the control thread for
    `log_arm`); each call sets its own time, so no rerun time state leaks between threads.
    """

    def __init__(self, path: Path, verb: str, mode: Mode, segment_s: float, view: bool,
                 connect_url: str | None, encode_threads: int) -> None:
        if mode not in MODES:
            raise InputError(f"recording mode '{mode}': expected one of {', '.join(MODES)}")
        if not (segment_s >= 0 and math.isfinite(segment_s)):
            raise InputError(f"recording segment length {segment_s!r}: expected a number >= 0 (s)")
        self.path = Path(path)
        self.verb, self.mode, self.segment_s = verb, mode, float(segment_s)
        self.replayable = mode != "preview"
        self.recording_id = str(uuid.uuid4())
        self.files: list[Path] = []     # finished files (segments get their final name)
        self._current: tuple[Path, Path] | None = None   # (being written, final name)
        self._grpc_url: str | None = None
        self._lock = threading.RLock()
        self._rec = rr.RecordingStream(APPLICATION_ID, recording_id=self.recording_id)
        self._static: list[tuple[str, list[Any]]] = []   # re-logged at each segment start
        self._seg_index = 0
        self._seg_t0: float | None = None
        self._path_pts: deque[tuple[float, np.ndarray]] = deque()
        self._path_last_t = -math.inf
        self._series: deque[tuple] = deque()   # (entity, t, frame, values) not yet written
        self._series_flushed_t = -math.inf
        self._arm_last: tuple[float, np.ndarray] | None = None
        self._arm_drawn_t = -math.inf
        self._closed = False
        self._error: BaseException | None = None
        self.frames_logged = 0
        self.encode_s = 0.0       # seconds spent encoding frames (any thread)
        self.wait_s = 0.0         # seconds the loop waited for a full encoder queue
        self._queue: queue.Queue | None = None
        self._workers: list[threading.Thread] = []
        if view or connect_url:
            self._grpc_url = connect_url or self._spawn_viewer()
        self._open_file(self._next_file())
        self._log_static("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP)
        self._log_static("world/rig", rr.AnnotationContext([
            rr.AnnotationInfo(id=0, label="inner", color=(0, 255, 0)),
            rr.AnnotationInfo(id=1, label="outer", color=(255, 0, 255))]))
        self._log_static("arm/q", rr.SeriesLines(names=list(JOINT_NAMES)))
        self._log_static("arm/setpoint", rr.SeriesLines(names=list(JOINT_NAMES)))
        self._log_static("arm/command", rr.SeriesLines(names=list(JOINT_NAMES)))
        self._log_static(E_RUN, rr.TextDocument(json.dumps(self._run_info(None, None), indent=1)))
        if not self.replayable:
            warnings.warn(f"{self.path}: {PREVIEW_WARNING}", stacklevel=3)
            self._log_static(E_WARNING, rr.TextDocument(PREVIEW_WARNING))
        self._preview_event_due = not self.replayable   # logged at the first frame's time
        if encode_threads > 0 and mode != "lossless":   # rr.Image copies at once: no thread
            self._queue = queue.Queue(maxsize=4 * encode_threads)
            for i in range(encode_threads):
                w = threading.Thread(target=self._encode_worker, name=f"recorder-encode-{i}",
                                     daemon=True)
                w.start()
                self._workers.append(w)

    # --- opening and closing -------------------------------------------------------------

    @classmethod
    def open(cls, path: str | Path | None, verb: str, *, mode: Mode = "lossless",
             segment_s: float = 0.0, view: bool = False, connect_url: str | None = None,
             logs_dir: str | Path = "logs", encode_threads: int = 1) -> Recorder:
        """Start a recording.

        path: the `.rrd` to write; None -> `default_path(verb, logs_dir)`. With `segment_s > 0`
            the files are `segment_path(path, 1..)` instead of `path` itself (module doc).
        mode: 'lossless' (raw pixels + rerun's LZ4), 'png' or 'preview' (JPEG, not replayable).
        view: spawn a viewer and stream to it while writing the file (returns at once).
        connect_url: stream to a running viewer (`rerun+http://host:9876/proxy`) as well.
        encode_threads: worker threads that encode png/preview frames (0: in the caller).
        """
        p = Path(path) if path is not None else default_path(verb, logs_dir)
        if p.suffix != ".rrd":
            raise InputError(f"{p}: a recording path must end in .rrd")
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise InputError(f"{p.parent}: cannot create the recording folder ({e.strerror})") from None
        if segment_s > 0:   # a reader would mix old and new files of the same name
            old = sorted(p.parent.glob(f"{glob.escape(p.stem)}.seg*.rrd")) + ([p] if p.exists() else [])
            if old:
                raise InputError(f"{old[0]}: a recording named {p.name} exists already; "
                                 "choose another path or remove it")
        return cls(p, verb, mode, segment_s, view, connect_url, encode_threads)

    @classmethod
    def from_config(cls, params: RecordingParams, verb: str, path: str | Path | None = None, *,
                    view: bool = False, connect_url: str | None = None) -> Recorder:
        """`open` with the [recording] config (mode, segment_s, dir); `path` overrides the
        default `<dir>/<UTC time>_<verb>.rrd`."""
        return cls.open(path, verb, mode=params.mode, segment_s=params.segment_s, view=view,
                        connect_url=connect_url, logs_dir=params.dir)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc is not None and not self._closed:
            try:
                self.event(self._last_t, f"session ended by {exc_type.__name__}: {exc}",
                           level="ERROR")
            except Exception:  # never mask the original exception
                log.exception("could not log the closing event")
        self.close()

    _last_t = 0.0

    def close(self) -> None:
        """Drain the encoder, flush, write the footer and disconnect. Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._queue is not None:
                for _ in self._workers:
                    self._queue.put(None)
                for w in self._workers:
                    w.join()
        finally:
            with self._lock:
                try:
                    if self._preview_event_due:
                        self._log(E_EVENTS, self._last_t, None, rr.TextLog(PREVIEW_WARNING, level="WARN"))
                    self._flush_series()
                    if self._arm_last is not None:
                        self._draw_arm(*self._arm_last)
                finally:
                    self._finish_file()
        if self._error is not None:
            raise RuntimeError(f"recording to {self.path} failed: {self._error}") from self._error

    # --- sinks and segments ---------------------------------------------------------------

    def _spawn_viewer(self, port: int = 9876) -> str | None:
        """Start a viewer process and return its gRPC URL (None if it cannot start: the
        recording then goes to the file only). rerun's spawn waits until the viewer listens;
        we wait at most SPAWN_WAIT_S for that, so a viewer that cannot come up (no display)
        never holds the session; data is buffered for it meanwhile."""
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

    def _next_file(self) -> Path:
        self._seg_index += 1
        return segment_path(self.path, self._seg_index) if self.segment_s > 0 else self.path

    @property
    def segment_index(self) -> int:
        """1-based number of the file being written."""
        return self._seg_index

    def _open_file(self, final: Path) -> None:
        """Point the stream at a new file and, if asked, at the viewer too; the blueprint goes
        with each file. A segment is written under its `.partial.rrd` name."""
        path = segment_path(self.path, self._seg_index, partial=True) if self.segment_s > 0 else final
        bp = blueprint()
        if self._grpc_url:
            self._rec.set_sinks(rr.GrpcSink(self._grpc_url), rr.FileSink(str(path)),
                                default_blueprint=bp)
        else:
            self._rec.save(path, default_blueprint=bp)
        self._current = (path, final)

    def _finish_file(self) -> None:
        """Flush, disconnect (rerun writes the footer and closes the file), then give a
        segment its final name: a `.segNNNN.rrd` is always complete."""
        if self._current is None:
            return
        try:
            self._rec.flush(timeout_sec=10.0)
        except Exception as e:  # noqa: BLE001 - an unreachable viewer must not cost the file
            log.warning("recording flush: %s", e)
        self._rec.disconnect()
        path, final = self._current
        self._current = None
        if path != final:
            path.replace(final)
        self.files.append(final)

    def _maybe_rotate(self, t: float) -> None:
        if self._seg_t0 is None:
            self._seg_t0 = t
            return
        if self.segment_s <= 0 or t - self._seg_t0 < self.segment_s - 1e-6:  # 1 us: float slack
            return
        if self._queue is not None:
            self._queue.join()   # this segment's frames land in this segment
        self._flush_series(t)
        with self._lock:
            self._finish_file()
            self._open_file(self._next_file())
            for entity, parts in self._static:
                self._rec.log(entity, *parts, static=True)
            self._seg_t0 = t
        self.event(t, f"segment {self._seg_index} starts")

    # --- low-level logging ----------------------------------------------------------------

    def _check(self) -> None:
        if self._error is not None:
            raise RuntimeError(f"recording to {self.path} failed: {self._error}") from self._error
        if self._closed:
            raise RuntimeError(f"recording to {self.path} is closed")

    def _log_static(self, entity: str, *parts: Any) -> None:
        with self._lock:
            self._static.append((entity, list(parts)))
            self._rec.log(entity, *parts, static=True)

    def _log(self, entity: str, t: float, frame: int | None, *parts: Any) -> None:
        with self._lock:
            self._rec.reset_time()
            if frame is not None:
                self._rec.set_time("frame", sequence=int(frame))
            self._rec.set_time("time", duration=float(t))
            self._rec.log(entity, *parts)

    def _encode_worker(self) -> None:
        assert self._queue is not None
        while True:
            item = self._queue.get()
            try:
                if item is None:
                    return
                if self._error is None:
                    self._encode_and_log(*item)
            except BaseException as e:  # noqa: BLE001 - reported to the caller at its next call
                self._error = e
            finally:
                self._queue.task_done()

    def _encode_and_log(self, frame: int, t: float, side: str, bgr: np.ndarray) -> None:
        t0 = time.perf_counter()
        image = encode_frame(bgr, self.mode)
        self.encode_s += time.perf_counter() - t0
        self._log(E_IMAGE[side], t, frame, image)

    def _run_info(self, seed: Any, versions: Mapping[str, str] | None) -> dict:
        return {"format": FORMAT_VERSION, "verb": self.verb, "mode": self.mode,
                "replayable": self.replayable, "seed": dict(seed) if isinstance(seed, Mapping) else seed,
                "versions": dict(versions or software_versions()),
                "recording_id": self.recording_id, "segment_s": self.segment_s,
                "started_utc": datetime.now(UTC).isoformat(timespec="seconds"),
                "png_params": PNG_PARAMS if self.mode == "png" else None,
                "layouts": {E_DATA_FRAME: FRAME_LAYOUT, E_DATA_EST: EST_LAYOUT,
                            E_DATA_TRUTH: TRUTH_LAYOUT}}

    # --- static setup ---------------------------------------------------------------------

    def log_static_setup(self, rig_toml_text: str | None, photo_bgr: np.ndarray | None = None,
                         model: Any = None, config_toml_text: str | None = None,
                         seed: int | Mapping[str, int] | None = None,
                         versions: Mapping[str, str] | None = None) -> None:
        """Everything replay needs besides the frames, logged static (and repeated in every
        segment): the rig (TOML text, and the Pinholes/stereo transform drawn from it), the
        photo (PNG) and its PhotoModel (every array, bit-exact), the effective config TOML,
        the seed (one int, or several by name, e.g. {"ga": 1, "world": 2}) and the software
        versions (default: `software_versions()`). Any part may be None (e.g. for `move`)."""
        self._check()
        with self._lock:
            self._static = [(e, p) for e, p in self._static if e != E_RUN]
            self._log_static(E_RUN, rr.TextDocument(json.dumps(self._run_info(seed, versions), indent=1)))
        if rig_toml_text is not None:
            import tomllib

            from photoservo.vision.rig import parse_rig
            rig = parse_rig(tomllib.loads(rig_toml_text), "recorded rig")
            self._log_static(E_RIG_TOML, rr.TextDocument(rig_toml_text))
            for side, cam in (("left", rig.left), ("right", rig.right)):
                self._log_static(E_CAM[side], rr.Pinhole(image_from_camera=cam.K, resolution=list(cam.size),
                                                          camera_xyz=rr.ViewCoordinates.RDF,
                                                          image_plane_distance=100.0))
            self._log_static(E_CAM["right"], rr.Transform3D(
                translation=rig.T, mat3x3=rig.R, relation=rr.TransformRelation.ChildFromParent))
        if config_toml_text is not None:
            self._log_static(E_CONFIG, rr.TextDocument(config_toml_text))
        if photo_bgr is not None:
            ok, buf = cv2.imencode(".png", photo_bgr)
            if not ok:
                raise ValueError("cannot encode the photo as PNG")
            self._log_static(E_PHOTO, rr.EncodedImage(contents=buf.tobytes(), media_type="image/png"))
        if model is not None:
            self._log_static(E_MODEL, rr.AnyValues(npz=_bytes_value(pack_arrays(model)),
                                                   type=type(model).__name__))
            o = np.asarray(model.origin_px, dtype=np.float64)
            self._log_static(f"{E_PHOTO}/inner", rr.Points2D(np.asarray(model.inner_uv) + o,
                                                               colors=[0, 255, 0], radii=1.0))
            self._log_static(f"{E_PHOTO}/outer", rr.Points2D(np.asarray(model.outer_uv) + o,
                                                               colors=[255, 0, 255], radii=1.0))

    # --- per-frame data -------------------------------------------------------------------

    def log_frame(self, frame: int, t: float, left_bgr: np.ndarray, right_bgr: np.ndarray,
                  *, T_base_left: np.ndarray | None = None,
                  capture_times: tuple[float, float] | None = None) -> None:
        """One stereo frame (BGR uint8) at loop time t (s): the images, and where the left
        camera was (T_base_left, 4x4 mm, the flange pose at capture times the hand-eye)."""
        self._check()
        self._maybe_rotate(t)
        self._last_t = t
        if self._preview_event_due:
            self._preview_event_due = False
            self.event(t, PREVIEW_WARNING, level="WARN")
        if t - self._series_flushed_t >= SERIES_FLUSH_S:
            self._flush_series(t)
        if self._arm_last is not None and t - self._arm_drawn_t >= ARM_DRAW_PERIOD_S:
            self._draw_arm(*self._arm_last)
        if T_base_left is not None:
            self._log("world/rig", t, frame, _transform(T_base_left))
        self._log(E_DATA_FRAME, t, frame, rr.AnyValues(values=pack(FRAME_LAYOUT, {
            "capture_times": capture_times, "T_base_left": T_base_left})))
        for side, img in (("left", left_bgr), ("right", right_bgr)):
            if self._queue is not None:
                t0 = time.perf_counter()
                self._queue.put((frame, t, side, np.array(img, copy=True)))
                self.wait_s += time.perf_counter() - t0
            else:
                self._encode_and_log(frame, t, side, np.asarray(img))
        self.frames_logged += 1

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
        projection: its projected points (`vision.fitness.ModelProjection`: inner_left,
        outer_left, inner_right, outer_right, px), drawn on the images when given (one
        Points2D per camera, class 0 = inner, 1 = outer, colours from the AnnotationContext).
        T_base_left places the model in the base frame for the 3-D view and truth errors."""
        self._check()
        self._last_t = t
        if fitness is not None:
            self._queue_scalar("plots/fitness", t, frame, float(fitness))
        self._queue_scalar("plots/found", t, frame, 1.0 if found else 0.0)
        posed = found and R is not None and position_mm is not None
        if posed:
            if alpha is not None:
                self._queue_scalar("plots/alpha", t, frame, float(alpha))
            T_left_model = make_pose(np.asarray(R, dtype=np.float64), np.asarray(position_mm, dtype=np.float64))
            T_base_model = T_left_model if T_base_left is None else np.asarray(T_base_left) @ T_left_model
            self._log_box("world/target/estimate", t, frame, T_base_model, size_mm, [255, 140, 0])
        else:
            self._log("world/target/estimate", t, frame, rr.Clear(recursive=False))
        for side in ("left", "right"):
            ent = f"{E_CAM[side]}/model"
            if found and projection is not None:
                inner = np.asarray(getattr(projection, f"inner_{side}"), dtype=np.float64).reshape(-1, 2)
                outer = np.asarray(getattr(projection, f"outer_{side}"), dtype=np.float64).reshape(-1, 2)
                uv = np.concatenate([inner, outer])
                ids = np.concatenate([np.zeros(len(inner), np.uint16), np.ones(len(outer), np.uint16)])
                ok = np.isfinite(uv).all(axis=1)
                self._log(ent, t, frame, rr.Points2D(uv[ok], class_ids=ids[ok], radii=1.5))
            else:
                self._log(ent, t, frame, rr.Clear(recursive=False))
        self._log(E_DATA_EST, t, frame, rr.AnyValues(values=pack(EST_LAYOUT, {
            "found": float(bool(found)), "fitness": fitness, "generations": generations,
            "alpha": alpha if posed else None, "rotation": R if posed else None,
            "position_mm": position_mm if posed else None, "size_mm": size_mm if posed else None,
            "T_base_left": T_base_left})))

    def _log_box(self, entity: str, t: float, frame: int | None, T: np.ndarray,
                 size_mm: Any, color: list[int]) -> None:
        """A pose (T_base_model) with axes and, if the size is known, the flat model box
        (drawn in the model frame: the entity's own transform applies to it)."""
        parts = [_transform(T), rr.TransformAxes3D(axis_length=30.0)]
        if size_mm is not None:
            w, h = (float(s) for s in size_mm)
            parts.append(rr.Boxes3D(half_sizes=[[w / 2, h / 2, 1.0]], colors=[color]))
        self._log(entity, t, frame, *parts)

    def log_truth(self, frame: int, t: float, T_base_target: np.ndarray,
                  size_mm: tuple[float, float] | None = None) -> None:
        """Simulation ground truth: the target's model frame in the base frame (4x4, mm)."""
        self._check()
        T = np.asarray(T_base_target, dtype=np.float64)
        self._log_box("world/target/truth", t, frame, T, size_mm, [0, 200, 255])
        self._log(E_DATA_TRUTH, t, frame, rr.AnyValues(values=pack(TRUTH_LAYOUT, {
            "T_base_target": T, "size_mm": size_mm})))

    def log_desired(self, t: float, T_base_cam_desired: np.ndarray, frame: int | None = None) -> None:
        """The desired (left) camera pose of the servo law, in the base frame (4x4, mm)."""
        self._check()
        self._log("world/target/desired", t, frame, _transform(T_base_cam_desired),
                  rr.TransformAxes3D(axis_length=60.0))

    def log_arm(self, t: float, q: np.ndarray, setpoint: np.ndarray | None = None,
                command: np.ndarray | None = None) -> None:
        """Joint state q (rad), the motion setpoint and the command sent (rad), at time t.

        Cheap enough for the control thread: the sample is only queued (a deque append, no
        rerun call, no lock). Queued series are written as columns every `SERIES_FLUSH_S` of
        frames, every `ARM_BATCH` samples when no frames come (the `move` verb), before a new
        segment and at close. The arm (forward kinematics of the latest q) is drawn at most
        every `ARM_DRAW_PERIOD_S`, with the flange path."""
        self._check()
        q = np.array(q, dtype=np.float64)
        self._series.append(("arm/q", float(t), None, q))
        if setpoint is not None:
            self._series.append(("arm/setpoint", float(t), None, np.array(setpoint, dtype=np.float64)))
        if command is not None:
            self._series.append(("arm/command", float(t), None, np.array(command, dtype=np.float64)))
        self._arm_last = (float(t), q)
        if len(self._series) >= ARM_BATCH and self._last_t < t - SERIES_FLUSH_S:   # no frames come
            self._flush_series(t)
            self._draw_arm(float(t), q)

    def log_timings(self, t: float, timings_ms: Mapping[str, float], frame: int | None = None) -> None:
        """Per-stage durations of one loop iteration (ms), as `timing/<stage>_ms` (queued like
        the other series)."""
        self._check()
        for stage, ms in timings_ms.items():
            self._queue_scalar(f"timing/{stage}_ms", t, frame, float(ms))

    @property
    def last_t(self) -> float:
        """Session time (s) of the newest frame or estimate logged: where a closing event goes."""
        return self._last_t

    def event(self, t: float, text: str, level: str = "INFO") -> None:
        """A line in the `events` text log (level: TRACE DEBUG INFO WARN ERROR CRITICAL)."""
        self._check()
        self._log(E_EVENTS, t, None, rr.TextLog(text, level=level))

    # --- batched series ---------------------------------------------------------------------

    def _queue_scalar(self, entity: str, t: float, frame: int | None, value: float) -> None:
        self._series.append((entity, float(t), frame, np.array([value])))

    def _flush_series(self, t: float | None = None) -> None:
        """Write the queued time series as one column chunk per entity (`send_columns`: a log
        call costs ~0.1-0.2 ms of Python in rerun, a column chunk about the same for any
        number of rows)."""
        rows = []
        while True:
            try:
                rows.append(self._series.popleft())
            except IndexError:
                break
        if t is not None:
            self._series_flushed_t = t
        if not rows:
            return
        by_entity: dict[str, list[tuple]] = {}
        for r in rows:
            by_entity.setdefault(r[0], []).append(r)
        with self._lock:
            for entity, rs in by_entity.items():
                indexes = [rr.TimeColumn("time", duration=[r[1] for r in rs])]
                if all(r[2] is not None for r in rs):
                    indexes.append(rr.TimeColumn("frame", sequence=[int(r[2]) for r in rs]))
                values = np.array([r[3] for r in rs])
                self._rec.send_columns(entity, indexes=indexes,
                                       columns=rr.Scalars.columns(scalars=values))

    def _draw_arm(self, t: float, q: np.ndarray) -> None:
        """The arm's link frames and skeleton at joint angles q, and the flange path."""
        frames = fk_frames(q)
        self._arm_drawn_t = t
        with self._lock:
            self._rec.reset_time()
            self._rec.set_time("time", duration=t)
            for i, T in enumerate(frames):
                self._rec.log(f"world/arm/link{i}", _transform(T), rr.TransformAxes3D(axis_length=40.0))
            self._rec.log("world/arm/skeleton", rr.LineStrips3D([frames[:, :3, 3]], radii=8.0,
                                                                   colors=[[200, 200, 200]]))
            self._path_pts.append((t, frames[-1, :3, 3].copy()))
            while self._path_pts and self._path_pts[0][0] < t - PATH_S:
                self._path_pts.popleft()
            if t - self._path_last_t >= PATH_PERIOD_S:
                self._path_last_t = t
                self._rec.log("world/flange/path", rr.LineStrips3D(
                    [np.array([p for _, p in self._path_pts])], radii=2.0, colors=[[255, 255, 0]]))
