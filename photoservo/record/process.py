"""A session's `Recorder` in its own process (issue 10), for the real-time verbs.

The recorder's work is Python beside the loop's: ~15 rerun calls a frame on its logging thread,
the planes' PNG and the video hand-over on two more. In the loop's process those threads took
the interpreter from the loop at every cv2 or numba call that released it (the tracker's GA
buys its generations with a wall-time budget), so the recording cost the loop about twice its
own CPU (benchmarks/track_speed.py: pre-rendered frames 64 fps, 25 with the recording).
`RecorderProcess` keeps the loop's side to what it must do: copy the frame's pixels and
fitness input into a free slot of a shared mapping (`shared_arrays.SharedArrays`,
RING_SLOTS frames) and send the small rest down a pipe. A child process runs the very
`Recorder` (same file, same content) on them and frees the slot once its own copies are made.
When every slot is taken (the child RING_SLOTS frames behind) the loop waits, as it waits for a
full planes queue in-process: each frame's planes are kept (replay needs them).

The API is the part of `Recorder`'s that sessions use (log_static_setup, log_frame,
log_estimate, log_truth, log_timings, log_arm, log_desired, event, close, path, written,
last_t); it is thread-safe (the control link's receiver thread logs the arm). An error in the
child is raised (RuntimeError) at the next call, as `Recorder` raises its workers' errors; a
bad path or mode is an InputError from the constructor, before anything is written. The child
ignores the stop signals (the session closes it) and, should the session die, closes the file
when the pipe ends.
"""

from __future__ import annotations

import multiprocessing
import threading
from multiprocessing import util
from pathlib import Path
from typing import Any

import numpy as np

from photoservo.errors import InputError
from photoservo.shared_arrays import SharedArrays

RING_SLOTS = 8   # frames the loop may be ahead of the recorder process before it waits
START_TIMEOUT_S = 60.0  # the child imports rerun and opens the recording (a loaded machine: seconds)


class RecorderProcess:
    """See the module docstring. The arguments are those of `Recorder.open` (the child opens it)."""

    def __init__(self, path: str | Path | None, verb: str, *, mode: str = "compact", video: str = "av1",
                 view: bool = False, connect_url: str | None = None, logs_dir: str | Path = "logs",
                 video_fps: float = 0.0) -> None:
        from photoservo.robot.clock import start_child

        ctx = multiprocessing.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._free = ctx.Semaphore(RING_SLOTS)
        args = dict(path=path, verb=verb, mode=mode, video=video, view=view, connect_url=connect_url,
                    logs_dir=logs_dir, video_fps=video_fps)
        # not daemonic: the recorder starts its video encoder process; `close` (or the finaliser
        # below, at exit) ends the pipe, and the child then ends
        self._proc = ctx.Process(target=_serve, args=(child, self._free, args), name="recorder", daemon=False)
        start_child(self._proc)
        child.close()
        self._lock = threading.Lock()
        self._ring: SharedArrays | None = None
        self._slot = 0
        self._error: str | None = None
        self._closed = False
        self._started = False
        self._last_t = 0.0
        self._finalize = util.Finalize(self, self._conn.close, exitpriority=10)
        kind, value = self._answer(START_TIMEOUT_S)
        if kind == "input":
            self._end()
            raise InputError(value)
        if kind != "ready":
            self._end()
            raise RuntimeError(f"the recorder process did not start: {value}")
        self.path = Path(value)

    @classmethod
    def from_config(cls, params: Any, verb: str, path: str | Path | None = None, *,
                    view: bool = False, connect_url: str | None = None) -> "RecorderProcess":
        """`Recorder.from_config` in its own process ([recording] mode, video, video_fps, dir)."""
        return cls(path, verb, mode=params.mode, video=params.video, view=view, connect_url=connect_url,
                   logs_dir=params.dir, video_fps=params.video_fps)

    # --- the pipe ---------------------------------------------------------------------------

    def _answer(self, timeout_s: float) -> tuple[str, Any]:
        """The child's next message (start and close are synchronous; errors come any time)."""
        if not self._conn.poll(timeout_s):
            return "error", f"no answer within {timeout_s:.0f} s"
        try:
            return self._conn.recv()
        except (EOFError, OSError):
            return "error", f"the recorder process ended (exit code {self._proc.exitcode})"

    def _check(self) -> None:
        if self._error is None and self._conn.poll():
            kind, value = self._answer(0.0)
            if kind == "error":
                self._error = value
        if self._error is not None:
            raise RuntimeError(f"recording to {self.path} failed: {self._error}")
        if self._closed:
            raise RuntimeError(f"recording to {self.path} is closed")

    def _call(self, name: str, *args: Any, **kwargs: Any) -> None:
        with self._lock:
            self._check()
            self._conn.send(("call", name, args, kwargs))

    # --- the Recorder's API -----------------------------------------------------------------

    @property
    def written(self) -> bool:
        """Whether the file exists: a frame, an estimate or an arm sample was logged."""
        return self._started

    @property
    def last_t(self) -> float:
        """Session time (s) of the newest frame or estimate logged: where a closing event goes."""
        return self._last_t

    def log_static_setup(self, *args: Any, **kwargs: Any) -> None:
        """`Recorder.log_static_setup` (the photo-model and the config are pickled to the child)."""
        self._call("log_static_setup", *args, **kwargs)

    def log_frame(self, frame: int, t: float, left_bgr: np.ndarray, right_bgr: np.ndarray, *,
                  T_base_left: np.ndarray | None = None, capture_times: tuple[float, float] | None = None,
                  fitness_input: Any = None) -> None:
        """`Recorder.log_frame`: the pixels (and the fitness input's hue planes) copied into a
        free slot of the shared mapping (waiting for one while the child is RING_SLOTS frames
        behind), the rest sent."""
        arrays = [left_bgr, right_bgr] + ([] if fitness_input is None else [fitness_input.left, fitness_input.right])
        arrays = [np.ascontiguousarray(a, np.uint8) for a in arrays]
        with self._lock:
            self._check()
            if self._ring is None:
                shapes = [a.shape for a in arrays] * RING_SLOTS
                self._ring = SharedArrays(SharedArrays.make_file(shapes, "photoservo-recorder-"), shapes)
                self._conn.send(("ring", self._ring.path, shapes))
            n = len(arrays)
            if [a.shape for a in arrays] != self._ring.shapes[:n] or len(self._ring.shapes) != n * RING_SLOTS:
                raise ValueError("log_frame: the frames' sizes (or the fitness input) changed within a recording")
        while not self._free.acquire(timeout=1.0):  # outside the lock: the arm's thread logs on meanwhile
            if not self._proc.is_alive():
                raise RuntimeError(f"recording to {self.path} failed: the recorder process ended "
                                   f"(exit code {self._proc.exitcode})")
        with self._lock:
            slot, self._slot = self._slot, (self._slot + 1) % RING_SLOTS
            for dst, src in zip(self._ring.arrays[slot * n:(slot + 1) * n], arrays):
                dst[...] = src
            T = None if T_base_left is None else np.array(T_base_left, dtype=np.float64)
            self._conn.send(("frame", frame, t, slot, n, T, capture_times))
            self._started, self._last_t = True, t

    def log_estimate(self, frame: int, t: float, **kwargs: Any) -> None:
        """`Recorder.log_estimate`."""
        self._call("log_estimate", frame, t, **kwargs)
        self._started, self._last_t = True, t

    def log_truth(self, *args: Any, **kwargs: Any) -> None:
        self._call("log_truth", *args, **kwargs)
        self._started = True

    def log_desired(self, *args: Any, **kwargs: Any) -> None:
        self._call("log_desired", *args, **kwargs)
        self._started = True

    def log_arm(self, *args: Any, **kwargs: Any) -> None:
        self._call("log_arm", *args, **kwargs)
        self._started = True

    def log_timings(self, *args: Any, **kwargs: Any) -> None:
        self._call("log_timings", *args, **kwargs)
        self._started = True

    def event(self, *args: Any, **kwargs: Any) -> None:
        """`Recorder.event` (events alone do not start the file)."""
        self._call("event", *args, **kwargs)

    def close(self) -> None:
        """`Recorder.close` in the child (drains its workers and encoders, writes the footer),
        then the child ends. Idempotent; raises the child's error, if any."""
        if self._closed:
            return
        with self._lock:
            self._closed = True
            try:
                self._conn.send(("close",))
                while True:  # an error message may come before the answer
                    kind, value = self._answer(300.0)
                    if kind == "error" and self._error is None and not str(value).startswith(("no answer", "the recorder")):
                        self._error = value
                        continue
                    break
                if kind == "closed":
                    self._started = value
                elif self._error is None:
                    self._error = value
            except OSError as e:
                self._error = self._error or f"the recorder process is gone ({e})"
            finally:
                self._end()
        if self._error is not None:
            raise RuntimeError(f"recording to {self.path} failed: {self._error}")

    def _end(self) -> None:
        self._finalize()  # closes our end of the pipe: a child still reading ends
        self._proc.join(timeout=30.0)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join()
        if self._ring is not None:
            self._ring.unlink()
            self._ring.close()
            self._ring = None

    def __enter__(self) -> "RecorderProcess":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc is not None and not self._closed:
            try:
                self.event(self._last_t, f"session ended by {exc_type.__name__}: {exc}", level="ERROR")
            except Exception:  # noqa: BLE001 - never mask the original exception
                pass
        self.close()


def _serve(conn, free, args: dict) -> None:
    """The child: a `Recorder` fed by the pipe until 'close' (or the pipe's end: the session is
    gone; the file is closed all the same)."""
    import cv2

    from photoservo.record.recorder import Recorder
    from photoservo.robot.clock import ignore_stop_signals
    from photoservo.vision.fitness import StereoHue

    ignore_stop_signals()
    cv2.setNumThreads(1)  # the planes' PNG beside the loop: no spin-waiting OpenCV pool
    try:
        rec = Recorder.open(**args)
    except InputError as e:
        conn.send(("input", str(e)))
        return
    except Exception as e:  # noqa: BLE001 - reported to the session, which raises it
        conn.send(("error", f"{type(e).__name__}: {e}"))
        return
    # the arm's drawing (`drawing.Drawing.arm`) runs the kinematics kernel: loaded now (~1 s of
    # CPU), while the session warms its own, not at its first drawing inside the session
    from photoservo.servo.warm import warm_kinematics
    warm_kinematics()
    conn.send(("ready", str(rec.path)))
    ring: SharedArrays | None = None
    failed = False
    try:
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):
                return
            if msg[0] == "close":
                break
            if msg[0] == "ring":
                ring = SharedArrays(msg[1], msg[2])
                continue
            try:
                if msg[0] == "frame":
                    _, frame, t, slot, n, T, capture_times = msg
                    try:
                        if not failed:
                            a = ring.arrays[slot * n:(slot + 1) * n]
                            rec.log_frame(frame, t, a[0], a[1], T_base_left=T, capture_times=capture_times,
                                          fitness_input=StereoHue(a[2], a[3]) if n == 4 else None)
                    finally:
                        free.release()  # the recorder has its own copies
                elif not failed:
                    _, name, a, kw = msg
                    getattr(rec, name)(*a, **kw)
            except Exception as e:  # noqa: BLE001 - the first error goes to the session; later calls are dropped
                if not failed:
                    failed = True
                    conn.send(("error", f"{type(e).__name__}: {e}"))
    finally:
        error = None
        try:
            rec.close()
        except Exception as e:  # noqa: BLE001
            error = f"{type(e).__name__}: {e}"
        if ring is not None:
            ring.close()
        try:
            conn.send(("closed", rec.written) if error is None or failed else ("error", error))
        except (OSError, ValueError):
            pass
