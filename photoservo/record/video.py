"""The watch-only camera video of a recording (compact and preview modes, issue 13).

Each camera's frames are encoded into a stream of samples that the Rerun viewer plays as a
`VideoStream` under the camera's Pinhole, so the 2-D views show the projected model points on
the video. PyAV (FFmpeg's encoders) does the encoding:

  av1   SVT-AV1, preset 12, CRF 40, low-delay prediction (one sample out per frame in), without
        the CDEF and loop-restoration filters and screen-content detection (a third less CPU at
        the same size and PSNR on simulator frames): the Rerun viewer decodes AV1 itself (built-in
        dav1d), nothing to install to watch it.
  h264  x264, ultrafast, zerolatency, CRF 28, Annex B: ~40 % less CPU than av1 here, but the
        native viewer decodes H.264 through an `ffmpeg` executable it needs on the PATH.

PyAV holds the GIL while it encodes (a thread encoding AV1 beside a Python loop halved that
loop's speed here), so a recorder encodes in a child process (`EncoderProcess`): the session's
loop keeps its interpreter to itself.

Lossy: the video is for watching. Replay reads the tracker's planes (`record.planes`) or full
frames, never the video. Keyframes every GOP_S seconds (the viewer decodes from the previous
one when it seeks); no B-frames (VideoStream does not take them).
"""

from __future__ import annotations

import multiprocessing
import os
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import cv2
import numpy as np

CODECS = ("av1", "h264", "none")
GOP_S = 2.0
#: FFmpeg encoder and its options per codec (measured in benchmarks/recording.py)
ENCODERS: dict[str, tuple[str, dict[str, str]]] = {
    "av1": ("libsvtav1", {"preset": "12", "crf": "40",
                          "svtav1-params": "pred-struct=1:lp=1:enable-cdef=0:enable-restoration=0:scm=0"}),
    "h264": ("libx264", {"preset": "ultrafast", "tune": "zerolatency", "crf": "28", "threads": "1"}),
}
MIN_SIDE = 64   # SVT-AV1 takes no smaller frame; smaller ones are padded (watch-only anyway)


@dataclass(frozen=True)
class Sample:
    """One encoded video sample: the frame index it shows, whether it starts a GOP, its codec."""

    frame: int
    data: bytes
    keyframe: bool
    codec: str


class VideoEncoder:
    """One camera's encoder: BGR uint8 frames in, `Sample`s out (in frame order)."""

    def __init__(self, codec: str, width: int, height: int, fps: float = 30.0) -> None:
        import av

        os.environ.setdefault("SVT_LOG", "1")   # SVT-AV1 prints a banner on stderr otherwise
        if codec not in ENCODERS:
            raise ValueError(f"video codec '{codec}': expected one of {', '.join(ENCODERS)}")
        self.codec, self.size = codec, (width, height)
        self.coded = (max(MIN_SIDE, width + width % 2), max(MIN_SIDE, height + height % 2))
        name, options = ENCODERS[codec]
        cc = av.CodecContext.create(name, "w")
        cc.width, cc.height = self.coded
        cc.pix_fmt = "yuv420p"
        rate = Fraction(round(fps * 1000), 1000)
        cc.time_base, cc.framerate = 1 / rate, rate
        cc.gop_size = max(1, round(GOP_S * fps))
        cc.max_b_frames = 0
        cc.options = dict(options)
        cc.open()
        self._cc: Any = cc
        self._av = av

    def encode(self, bgr: np.ndarray, frame: int) -> list[Sample]:
        """Encode one frame (its loop frame index becomes the sample's pts)."""
        h, w = bgr.shape[:2]
        if (w, h) != self.size:
            raise ValueError(f"video frame is {w}x{h}, the stream is {self.size[0]}x{self.size[1]}")
        if self.coded != self.size:
            bgr = np.pad(bgr, ((0, self.coded[1] - h), (0, self.coded[0] - w), (0, 0)), mode="edge")
        # BT.601 4:2:0 by cv2 (a quarter of swscale's CPU for bgr24 -> yuv420p here)
        vf = self._av.VideoFrame.from_ndarray(cv2.cvtColor(np.ascontiguousarray(bgr), cv2.COLOR_BGR2YUV_I420),
                                              format="yuv420p")
        vf.pts = frame
        return self._samples(self._cc.encode(vf))

    def flush(self) -> list[Sample]:
        """The samples still inside the encoder (none for the low-delay settings above)."""
        return self._samples(self._cc.encode(None))

    def _samples(self, packets: Any) -> list[Sample]:
        return [Sample(int(p.pts), bytes(p), bool(p.is_keyframe), self.codec) for p in packets]


def decode_samples(codec: str, samples: list[bytes]) -> list[np.ndarray]:
    """Decode a camera's samples back to BGR frames (tests and tools; the viewer has its own)."""
    import av

    cc = av.CodecContext.create({"av1": "libdav1d", "h264": "h264"}[codec], "r")
    out = []
    for data in samples:
        for f in cc.decode(av.Packet(data)):
            out.append(f.to_ndarray(format="bgr24"))
    for f in cc.decode(None):
        out.append(f.to_ndarray(format="bgr24"))
    return out


class EncoderProcess:
    """`VideoEncoder`s, one per camera side, in a child process: frames go down a pipe as raw
    bytes, samples come back. Not thread-safe: one caller thread (the recorder's video worker).
    The child ignores the stop signals (the session stops it through `close`) and exits when the
    pipe closes, so a killed session leaves no encoder behind."""

    def __init__(self, codec: str, fps: float) -> None:
        from photoservo.robot.clock import start_child

        if codec not in ENCODERS:
            raise ValueError(f"video codec '{codec}': expected one of {', '.join(ENCODERS)}")
        ctx = multiprocessing.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_serve, args=(child, codec, fps), name="recorder-video", daemon=True)
        start_child(self._proc)
        child.close()

    def encode(self, side: str, bgr: np.ndarray, frame: int) -> list[Sample]:
        """`VideoEncoder.encode` of this side's encoder (made at its first frame)."""
        img = np.ascontiguousarray(bgr, np.uint8)
        self._conn.send(("encode", side, frame, img.shape))
        self._conn.send_bytes(memoryview(img).cast("B"))
        return self._answer()

    def flush(self, side: str) -> list[Sample]:
        """`VideoEncoder.flush` of this side's encoder (nothing if it never had a frame)."""
        self._conn.send(("flush", side))
        return self._answer()

    def close(self) -> None:
        """Stop the child (it has flushed nothing on its own: `flush` each side first)."""
        try:
            self._conn.send(("stop",))
        except OSError:
            pass
        self._proc.join(timeout=10.0)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join()
        self._conn.close()

    def _answer(self) -> list[Sample]:
        try:
            kind, value = self._conn.recv()
        except EOFError:
            raise RuntimeError(f"the video encoder process ended (exit code {self._proc.exitcode})") from None
        if kind == "error":
            raise RuntimeError(f"video encoder: {value}")
        return value


def _serve(conn, codec: str, fps: float) -> None:
    """The child of `EncoderProcess`: encode what the pipe brings until 'stop' or EOF."""
    from photoservo.robot.clock import ignore_stop_signals

    ignore_stop_signals()
    cv2.setNumThreads(1)  # its colour conversion beside the loop: no spin-waiting OpenCV pool
    encoders: dict[str, VideoEncoder] = {}
    while True:
        try:
            msg = conn.recv()
        except EOFError:
            return
        if msg[0] == "stop":
            return
        try:
            if msg[0] == "encode":
                _, side, frame, shape = msg
                img = np.frombuffer(conn.recv_bytes(), np.uint8).reshape(shape)
                enc = encoders.get(side)
                if enc is None:
                    enc = encoders[side] = VideoEncoder(codec, shape[1], shape[0], fps)
                conn.send(("samples", enc.encode(img, frame)))
            else:
                enc = encoders.get(msg[1])
                conn.send(("samples", enc.flush() if enc is not None else []))
        except Exception as e:  # noqa: BLE001 - reported to the parent, which raises it
            conn.send(("error", f"{type(e).__name__}: {e}"))
