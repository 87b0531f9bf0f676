"""Frames encoded off the loop (compact and preview modes, issue 13), for `record.recorder`.

Two worker threads: `planes` encodes the tracker's planes (`record.planes`, compact mode) of
every frame, losslessly: replay needs each one, so the loop waits when QUEUE_FRAMES frames are
already waiting (counted in `wait_s`). `video` encodes both cameras' watch-only video
(`record.video`) and never holds the loop up: while it is more than VIDEO_LAG_S of loop time
behind, frames are left out of the video (counted in `video_dropped`), so on a machine short of
CPU the video's frame rate falls and the loop's does not (a test or a lockstep run, which logs
frames faster or slower than real time but never that far ahead of the worker, keeps them
all). The video also keeps at most `video_fps` frames a second ([recording] video_fps; 0 =
every frame): encoding is most of a recording's CPU (benchmarks/recording.py). cv2 releases the GIL while it encodes the planes; PyAV does not,
so the video is encoded in a child process (`video.EncoderProcess`). The workers thus use a
spare core while the loop runs; the loop copies the frame, hands it over and goes on.
"""

from __future__ import annotations

import dataclasses
import queue
import threading
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from photoservo.record import layout as L
from photoservo.record.layout import rr

QUEUE_FRAMES = 8       # frames waiting for the planes worker before the loop waits
VIDEO_LAG_S = 0.5       # loop time (s) the video worker may lag before frames are left out of the video


class Worker:
    """A thread that runs queued jobs in order; the first error is kept for the caller."""

    def __init__(self, name: str, size: int) -> None:
        self.queue: queue.Queue = queue.Queue(maxsize=size)
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

    def __init__(self, rec: Any, planes: bool, video: str, video_fps: float = 0.0) -> None:
        self.rec, self.planes, self.video, self.video_fps = rec, planes, video, video_fps
        self._video_slot = -1                        # the last video frame slot encoded (video_fps)
        self.workers = {"planes": Worker("recorder-planes", QUEUE_FRAMES),
                        "video": Worker("recorder-video", 0)}
        self.hue_lut: np.ndarray | None = None       # compact: hue -> class (`planes`)
        self.target_hues: np.ndarray | None = None
        self.fitness: Any = None                     # [fitness] params of the recorded config
        self.layout_share = 0.0                      # [estimator] layout_share of the recorded config
        self.encoder: Any = None                     # `video.EncoderProcess`, at the first video frame
        self.codec: dict[str, str] = {}              # side -> codec of the logged stream
        self.frame_t: dict[tuple[str, int], float] = {}   # (side, frame) -> t, until its sample
        self.wait_s = 0.0         # seconds the loop waited for a full planes queue
        self.video_dropped = 0    # frames due in the video but left out (video worker behind)
        self._video_queued_t: list[float] = []   # loop times of the frames the video worker has
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
        """Hand a frame to the workers: its planes always, its video when due and the video
        worker keeps up (module docstring). The images and the fitness input must be the
        recorder's own copies."""
        if self.planes:
            fitness_input = fitness_input if fitness_input is not None else self._fitness_input(left, right)
            t0 = time.perf_counter()
            self.workers["planes"].queue.put(lambda: self._encode_planes(frame, t, fitness_input, left, right))
            self.wait_s += time.perf_counter() - t0
        if video is not None:
            self.workers["video"].queue.put(lambda: [self.log_samples(s, video.get(s, []), t) for s in L.SIDES])
        elif self.video != "none" and self._video_due(t):
            waiting = self._video_queued_t
            if waiting and t - waiting[0] > VIDEO_LAG_S:
                self.video_dropped += 1
                return
            waiting.append(t)

            def encode() -> None:
                try:
                    for side, img in zip(L.SIDES, (left, right)):
                        self._encode_video(side, img, frame, t)
                finally:
                    waiting.remove(t)

            self.workers["video"].queue.put(encode)

    def _video_due(self, t: float) -> bool:
        """Whether a frame at loop time t (s) is due in the video: every frame when video_fps
        is 0, else the first frame in each 1/video_fps slot."""
        if self.video_fps <= 0:
            return True
        slot = int(np.floor(t * self.video_fps))
        if slot <= self._video_slot:
            return False
        self._video_slot = slot
        return True

    def close(self) -> None:
        """Finish every queued frame, then the encoders' last samples."""
        for w in self.workers.values():
            w.stop()
        if self.encoder is not None:
            try:
                if self.error is None:
                    for side in L.SIDES:
                        self.log_samples(side, self.encoder.flush(side))
            finally:
                self.encoder.close()

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
        if self.encoder is None:
            from photoservo.record.video import EncoderProcess
            self.encoder = EncoderProcess(self.video, self.video_fps if self.video_fps > 0 else 30.0)
        samples = self.encoder.encode(side, bgr, frame)
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


def copied(obj: Any) -> Any:
    """A copy of a dataclass of arrays (the fitness input) that the caller cannot change (a field
    left None stays None)."""
    return dataclasses.replace(obj, **{f.name: np.array(getattr(obj, f.name), copy=True)
                                       for f in dataclasses.fields(obj)
                                       if f.init and getattr(obj, f.name) is not None})

