"""Frames encoded off the loop (compact and preview modes, issue 13), for `record.recorder`.

Two worker threads, one per camera: each encodes its camera's watch-only video
(`record.video`); the right one also the tracker's planes (`record.planes`, compact mode). cv2
and PyAV release the GIL, so the workers use the second core while the loop runs. The loop
copies the frame, hands it over and goes on; it waits only when QUEUE_FRAMES frames are
already waiting (counted in `wait_s`).
"""

from __future__ import annotations

import dataclasses
import queue
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from photoservo.record import layout as L
from photoservo.record.layout import rr

QUEUE_FRAMES = 8       # frames waiting for a worker before the loop waits


class _Worker:
    """A thread that runs queued jobs in order; the first error is kept for the caller."""

    def __init__(self, name: str) -> None:
        self.queue: queue.Queue = queue.Queue(maxsize=QUEUE_FRAMES)
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name=name, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while True:
            job = self.queue.get()
            try:
                if job is None:
                    return
                if self.error is None:
                    job()
            except BaseException as e:  # noqa: BLE001 - reported to the caller at its next call
                self.error = e
            finally:
                self.queue.task_done()

    def stop(self) -> None:
        self.queue.put(None)
        self.thread.join()


class FrameEncoding:
    """The compact / preview part of a recording; logs through the recorder's `_log`."""

    def __init__(self, rec: Any, planes: bool, video: str) -> None:
        self.rec, self.planes, self.video = rec, planes, video
        self.workers = {s: _Worker(f"recorder-{s}") for s in L.SIDES}
        self.hue_lut: np.ndarray | None = None       # compact: hue -> class (`planes`)
        self.target_hues: np.ndarray | None = None
        self.fitness: Any = None                     # [fitness] params of the recorded config
        self.layout_share = 0.0                      # [estimator] layout_share of the recorded config
        self.encoders: dict[str, Any] = {}
        self.codec: dict[str, str] = {}              # side -> codec of the logged stream
        self.frame_t: dict[tuple[str, int], float] = {}   # (side, frame) -> t, until its sample
        self.wait_s = 0.0         # seconds the loop waited for a full worker queue
        self.encode_s = 0.0       # seconds the workers spent encoding planes and video

    def set_model(self, model: Any, fitness: Any) -> None:
        """The photo-model and [fitness] params that decide the hue classes."""
        from photoservo.record.planes import hue_class_lut
        self.target_hues = np.asarray(model.target_hues, bool)
        if fitness is not None:
            self.fitness = fitness
            self.hue_lut = hue_class_lut(model.inner_hue, model.target_hues, fitness.hue_tolerance)

    @property
    def error(self) -> BaseException | None:
        return next((w.error for w in self.workers.values() if w.error is not None), None)

    def queue(self, frame: int, t: float, left: np.ndarray, right: np.ndarray,
              fitness_input: Any, video: Mapping[str, list] | None) -> None:
        """Hand a frame (copies of its images) to the workers: video per camera, planes on the
        right worker."""
        if self.planes:
            fitness_input = _copied(fitness_input if fitness_input is not None
                                    else self._fitness_input(left, right))
        for side, img in (("left", left), ("right", right)):
            jobs: list[Callable[[], None]] = []
            if video is not None:
                jobs.append(lambda s=side: self.log_samples(s, video.get(s, []), t))
            elif self.video != "none":
                jobs.append(lambda s=side, im=img: self._encode_video(s, im, frame, t))
            if self.planes and side == "right":
                jobs.append(lambda: self._encode_planes(frame, t, fitness_input, left, right))
            t0 = time.perf_counter()
            for job in jobs:
                self.workers[side].queue.put(job)
            self.wait_s += time.perf_counter() - t0

    def close(self) -> None:
        """Finish every queued frame, then the encoders' last samples."""
        for w in self.workers.values():
            w.stop()
        for side, enc in self.encoders.items():
            self.log_samples(side, enc.flush())

    def _fitness_input(self, left: np.ndarray, right: np.ndarray) -> Any:
        from photoservo.vision.fitness import stereo_hue
        if self.fitness is None:
            from photoservo.config import load_config
            self.fitness = load_config().fitness
        return stereo_hue(left, right, self.fitness)

    def _encode_planes(self, frame: int, t: float, fitness_input: Any, left: np.ndarray,
                       right: np.ndarray) -> None:
        from photoservo.record.planes import encode_planes, frame_lut, tracker_planes
        t0 = time.perf_counter()
        lut = frame_lut(self.hue_lut, fitness_input.left, self.target_hues, self.layout_share)
        blob = encode_planes(tracker_planes(fitness_input, left, right, lut, self.target_hues))
        self.encode_s += time.perf_counter() - t0
        self.rec._log(L.E_PLANES, t, frame, rr.AnyValues(planes=L.blob(blob)))

    def _encode_video(self, side: str, bgr: np.ndarray, frame: int, t: float) -> None:
        t0 = time.perf_counter()
        enc = self.encoders.get(side)
        if enc is None:
            from photoservo.record.video import VideoEncoder
            enc = self.encoders[side] = VideoEncoder(self.video, bgr.shape[1], bgr.shape[0])
        samples = enc.encode(bgr, frame)
        self.encode_s += time.perf_counter() - t0
        self.frame_t[(side, frame)] = t
        self.log_samples(side, samples)

    def log_samples(self, side: str, samples: list, t: float | None = None) -> None:
        """Log video samples at their frames' times (`t` for all of them when given); the
        codec, static, before the first."""
        for s in samples:
            if side not in self.codec:
                self.codec[side] = s.codec
                codec = {"av1": rr.VideoCodec.AV1, "h264": rr.VideoCodec.H264}[s.codec]
                self.rec._log_static(L.E_VIDEO[side], rr.VideoStream(codec=codec))
            ts = self.frame_t.pop((side, s.frame), self.rec._last_t) if t is None else t
            self.rec._log(L.E_VIDEO[side], ts, s.frame,
                          rr.VideoStream.from_fields(sample=s.data, is_keyframe=s.keyframe))


def _copied(obj: Any) -> Any:
    """A copy of a dataclass of arrays (the fitness input) that the caller cannot change."""
    return dataclasses.replace(obj, **{f.name: np.array(getattr(obj, f.name), copy=True)
                                       for f in dataclasses.fields(obj) if f.init})

