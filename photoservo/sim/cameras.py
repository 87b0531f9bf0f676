"""The simulator's stereo cameras in real time (issue 5, Simulator): a `StereoSource`
(vision/sources.py) like a camera with its own electronics. A shutter thread exposes a pair at
the camera rate — the time is the monotonic clock then, the pose where the emulated arm truly is
(its bridge's joint state) — and a renderer process (its own core) delivers the images while the
loop works on the previous pair. One exposure is in flight at a time; the loop learns where the
cameras were from the arm's states, as on hardware.

The images come through a shared file mapping (`FrameBuffer`), like a frame grabber's DMA buffer;
the pipe carries only the requests and a "ready" word. Pickled through the pipe, a 640x480 pair
(1.8 MB) cost the loop 19 ms a frame on a busy machine (64 KB at a time, a context switch each)
and blocked the renderer until the loop read it.
"""

from __future__ import annotations

import mmap
import multiprocessing
import os
import tempfile
import threading
import time
from collections import deque
from dataclasses import dataclass

import cv2
import numpy as np

from photoservo.robot import pa10
from photoservo.robot.clock import ignore_stop_signals, start_child
from photoservo.sim.world import SimScene
from photoservo.vision.sources import StereoSource


@dataclass(frozen=True)
class SimCamerasConfig:
    """The simulated pair's timing (from [sim]): frame rate (Hz), the right camera's exposure
    delay after the left (s); `read()` gives up after timeout_s."""

    camera_fps: float
    lr_skew_s: float
    timeout_s: float = 1.0
    max_skew_s: float = 1.0


class FrameBuffer:
    """A stereo pair's pixels in a file mapping that the renderer process writes and the
    session's loop reads: `create` makes the file (in /dev/shm where there is one), `attach`
    maps it in the other process, `unlink` removes its name once both have it mapped (the
    mapping lives on until both close it; a killed session leaves no file behind after that).
    `images` are the (H, W, 3) uint8 views of the left and right image. Not the standard library's
    multiprocessing.shared_memory.SharedMemory: on Python 3.11 its resource tracker registers the
    segment in the attaching process too and unlinks it (with a warning) when either exits
    (`track=False` arrives in 3.13); a named file that is unlinked once both have mapped it has
    neither problem."""

    def __init__(self, path: str, sizes: tuple[tuple[int, int], tuple[int, int]]) -> None:
        self.path, self.sizes = path, sizes
        shapes = [(h, w, 3) for w, h in sizes]
        n = [h * w * 3 for h, w, _ in shapes]
        with open(path, "r+b") as f:
            self._map = mmap.mmap(f.fileno(), sum(n))
        self.images = [np.ndarray(shapes[0], np.uint8, self._map, 0), np.ndarray(shapes[1], np.uint8, self._map, n[0])]

    @classmethod
    def create(cls, sizes: tuple[tuple[int, int], tuple[int, int]]) -> "FrameBuffer":
        """A new buffer for images of `sizes` ((w, h) left, right)."""
        folder = "/dev/shm" if os.path.isdir("/dev/shm") else None
        fd, path = tempfile.mkstemp(prefix="photoservo-frames-", dir=folder)
        with os.fdopen(fd, "wb") as f:
            f.truncate(sum(w * h * 3 for w, h in sizes))
        return cls(path, sizes)

    def unlink(self) -> None:
        try:
            os.unlink(self.path)
        except FileNotFoundError:
            pass

    def close(self) -> None:
        self.images = []
        self._map.close()


def render_process(make_scene, requests, frames, buffer: tuple[str, tuple]) -> None:
    """The renderer in its own process: builds the scene (`make_scene()`, deterministic from the
    config) and renders each request (T_base_left, t_left, T_base_left_at_right, t_right) — the
    order of `SimScene.render`'s arguments, as the shutter sends them — into a stereo pair, written
    into the `FrameBuffer` at buffer = (path, sizes); each pair is announced on `frames`."""
    ignore_stop_signals()  # the session stops it
    # one thread, like a camera's own electronics: OpenCV's worker pool spin-waits between calls
    # (+10 % CPU per frame here) on the cores the vision loop needs
    cv2.setNumThreads(1)
    scene: SimScene = make_scene()
    out = FrameBuffer(*buffer)
    scene.warm()  # compile or load the renderer's kernel before the session's clock starts
    frames.send(("ready",))
    while True:
        try:
            msg = requests.recv()
        except (EOFError, OSError):  # the session process is gone
            return
        if msg is None:
            return
        for img, view in zip(scene.render(*msg), out.images):
            view[...] = img
        frames.send(True)


class SimCameras(StereoSource):
    """See the module docstring. `connect()` starts the renderer process (`make_scene` must be
    picklable: it runs there), `wait_ready()` waits for it to have warmed its kernel, `start(t0)`
    starts the exposures (scene time = monotonic time - t0). `sizes`: (w, h) of the left and
    right images (the rig's)."""

    def __init__(self, config: SimCamerasConfig, make_scene, emulator, T_flange_left: np.ndarray,
                 sizes: tuple[tuple[int, int], tuple[int, int]]) -> None:
        super().__init__(config)
        self.make_scene, self.emulator, self.T_fl, self.t0 = make_scene, emulator, T_flange_left, 0.0
        self.sizes = sizes  # (w, h) of the left and right images
        self._buffer: FrameBuffer | None = None
        self.period, self.skew = 1.0 / config.camera_fps, config.lr_skew_s
        self._proc = None
        self._cond = threading.Condition()
        self._in_flight: deque[float] = deque()
        self._t_next = 0.0  # monotonic time of the next exposure
        self._stop = False
        self._shutter = threading.Thread(target=self._expose, name="sim-shutter", daemon=True)

    @property
    def is_connected(self) -> bool:
        return self._proc is not None and self._proc.is_alive()

    def connect(self) -> None:
        ctx = multiprocessing.get_context("spawn")
        self._req_rx, self._req_tx = ctx.Pipe(duplex=False)
        self._frm_rx, self._frm_tx = ctx.Pipe(duplex=False)
        self._buffer = FrameBuffer.create(self.sizes)
        self._proc = ctx.Process(target=render_process, name="photoservo-cameras", daemon=True,
                                 args=(self.make_scene, self._req_rx, self._frm_tx, (self._buffer.path, self.sizes)))
        start_child(self._proc)  # it compiles or loads its kernel meanwhile: see wait_ready

    def wait_ready(self, timeout_s: float = 300.0) -> None:
        """Wait until the renderer process has built the scene and warmed its kernel (a first run
        compiles it: seconds, more on a loaded machine)."""
        if not self._frm_rx.poll(timeout_s):
            raise RuntimeError(f"the simulated cameras' renderer did not start within {timeout_s:.0f} s")
        self._frm_rx.recv()
        self._buffer.unlink()  # both processes have it mapped

    def start(self, t0: float) -> None:
        """Start exposing (after `wait_ready`); scene time is monotonic time minus t0."""
        self.t0 = t0
        self._shutter.start()

    def _expose(self) -> None:
        """The shutter: an exposure every camera period while none is in flight (`_grab_pair`
        exposes the next itself when it takes a pair after its time has come)."""
        with self._cond:
            self._t_next = time.monotonic()
            while True:
                while not self._stop and (self._in_flight or time.monotonic() < self._t_next):
                    self._cond.wait(max(0.0, min(0.05, self._t_next - time.monotonic())) or 0.05)
                if self._stop:
                    return
                self._expose_now()

    def _expose_now(self) -> None:
        """Expose a pair now (with `_cond` held): the time, the left camera where the emulated arm
        truly is, the request to the renderer process; the next exposure one period later."""
        t_l = time.monotonic()
        T_l = pa10.fk(self.emulator.true_state().q) @ self.T_fl
        self._in_flight.append(t_l)
        self._req_tx.send((T_l, t_l - self.t0, T_l, t_l + self.skew - self.t0))
        self._t_next = max(self._t_next + self.period, t_l - self.period)

    def _grab_pair(self) -> tuple[np.ndarray, np.ndarray, float, float] | None:
        """The next rendered pair (left, right, t_left, t_right), or None after the timeout. A
        loop slower than the camera rate takes each pair after the next exposure is due: this
        thread exposes it at once (the shutter thread would wait for the interpreter lock while
        the loop works: the renderer would idle), so the renderer works while the loop does."""
        if not self._frm_rx.poll(self.config.timeout_s):
            return None
        self._frm_rx.recv()
        left, right = (img.copy() for img in self._buffer.images)  # before the next exposure is sent
        with self._cond:
            t_l = self._in_flight.popleft()
            if not self._stop and self._shutter.is_alive() and time.monotonic() >= self._t_next:
                self._expose_now()
            self._cond.notify_all()
        return left, right, t_l, t_l + self.skew

    def disconnect(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._shutter.is_alive():
            self._shutter.join(timeout=2.0)
        if self._proc is None:
            return
        try:
            self._req_tx.send(None)
        except (OSError, ValueError):
            pass
        self._proc.join(timeout=5.0)
        if self._proc.is_alive():  # it ignores SIGTERM (ignore_stop_signals)
            self._proc.kill()
        self._proc = None
        if self._buffer is not None:
            self._buffer.unlink()
            self._buffer.close()
            self._buffer = None
