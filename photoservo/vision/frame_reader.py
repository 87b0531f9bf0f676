"""The newest stereo pair of a source, read on a background thread (vision/sources.py):
`LatestFrameReader`, for a loop slower than its cameras (`track` on hardware)."""

from __future__ import annotations

import threading
from typing import Self

from photoservo.vision.sources import EndOfStream, SourceNotConnectedError, StereoFrame, StereoSource


class LatestFrameReader:
    """Reads a source on a background thread and hands out only the newest pair: a loop that
    is slower than the cameras gets fresh frames instead of a growing backlog (LeRobot's
    `async_read`). Pairs replaced before anyone took them are counted in `overwritten`.

        with LatestFrameReader(make_source(cfg)) as reader:
            frame = reader.latest(timeout_s=0.1)   # None on timeout (counted in source.stats)

    The source is connected and disconnected by the reader. Errors in the thread (other than
    the end of a finite source) are raised again by the next `latest()`.
    """

    def __init__(self, source: StereoSource) -> None:
        self.source = source
        self.overwritten = 0
        self._cond = threading.Condition()
        self._frame: StereoFrame | None = None
        self._ended = False
        self._error: BaseException | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Connect the source and start reading.

        Raises:
            InputError: the source cannot be opened.
        """
        self.source.connect()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="stereo-reader", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread and disconnect the source. Safe to call twice."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=max(2.0, 2 * self.source.config.timeout_s))
            self._thread = None
        self.source.disconnect()

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                frame = self.source.read()
                if frame is None:
                    continue
                with self._cond:
                    if self._frame is not None:
                        self.overwritten += 1
                    self._frame = frame
                    self._cond.notify_all()
        except EndOfStream:
            pass
        except Exception as e:  # noqa: BLE001 - handed to the consumer by latest()
            self._error = e
        with self._cond:
            self._ended = True
            self._cond.notify_all()

    def latest(self, timeout_s: float | None = None) -> StereoFrame | None:
        """The newest pair not yet returned, waiting up to `timeout_s` (None: the source's
        timeout_s) for one. Returns None on timeout.

        Raises:
            EndOfStream: a finite source ended and its last pair was taken.
            SourceNotConnectedError: `start()` was not called.
        """
        if self._thread is None:
            raise SourceNotConnectedError("LatestFrameReader is not started: call start() first")
        wait = self.source.config.timeout_s if timeout_s is None else timeout_s
        with self._cond:
            self._cond.wait_for(lambda: self._frame is not None or self._ended, timeout=wait)
            frame, self._frame = self._frame, None
            if frame is None:
                if self._error is not None:
                    raise self._error
                if self._ended:
                    raise EndOfStream
                self.source.stats.timeouts += 1
            return frame

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
