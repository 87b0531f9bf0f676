"""Reading recordings back (issues 6, 12 and 13): the reading side of replay.

`read_recording(path)` reads a `.rrd` written by `record.recorder.Recorder` with
`rerun.chunk.RrdReader` (rerun-sdk 0.41; `rerun.dataframe` no longer exists) into plain
dataclasses: the static setup (rig TOML, effective config TOML, photo, PhotoModel, seed,
versions), the per-frame metadata, estimates, ground truth, arm series (rad), timings and
events. `iter_frames(path)` streams the frames in frame order: full frames decoded exactly as
logged, the tracker's planes (compact mode, `record.planes`) and the video samples;
`read_recording(path, images=True)` loads them all (short recordings).

A recording cut short (the process that wrote it was killed, or the disk filled) lacks rerun's
footer, and may end inside a message; it is read as far as its complete messages go, and
`Recording.truncated` says what is missing (`describe_truncation` for a one-line report).
"""

from __future__ import annotations

import dataclasses
import io
import json
import re
import tempfile
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
from rerun.chunk import RrdReader

from photoservo.errors import InputError
from photoservo.record import layout as L
from photoservo.geometry import make_pose


@dataclass
class Setup:
    """The static part of a recording: enough to rebuild rig, photo-model, config and seed."""

    run: dict                       # setup/run JSON: verb, mode, replayable, seed, versions...
    rig_toml: str | None
    config_toml: str | None
    photo_bgr: np.ndarray | None
    model: Any                      # vision.photo_model.PhotoModel, bit-exact, or None
    warning: str | None = None      # the preview-mode warning, if any

    @property
    def seed(self) -> int | dict | None:
        """The seed as logged: one int, or a dict of named seeds."""
        return self.run.get("seed")

    def rig(self) -> Any:
        """The recorded rig (`vision.rig.Rig`), or None."""
        if self.rig_toml is None:
            return None
        import tomllib

        from photoservo.vision.rig import parse_rig
        return parse_rig(tomllib.loads(self.rig_toml), "recorded rig")

    @property
    def versions(self) -> dict:
        return self.run.get("versions", {})

    @property
    def replayable(self) -> bool:
        return bool(self.run.get("replayable", False))

    @property
    def full_frames(self) -> bool:
        """Whether the frames' pixels were kept (full mode; format 1's lossless/png modes)."""
        return bool(self.run.get("full_frames", self.run.get("mode") in ("lossless", "png")))


@dataclass
class FrameMeta:
    """One logged stereo frame without its pixels: loop time t (s), where the left camera was."""

    index: int
    t: float
    T_base_left: np.ndarray | None = None
    capture_times: tuple[float, float] | None = None


@dataclass
class Frame:
    """One stereo frame read back: the full BGR frames (full mode, exactly as logged), the
    tracker's planes (compact mode) and the video samples per side (`video.Sample`)."""

    index: int
    t: float
    left: np.ndarray | None = None
    right: np.ndarray | None = None
    planes: dict[str, np.ndarray] | None = None
    video: dict[str, list] = field(default_factory=dict)


@dataclass
class EstimateRecord:
    """The tracker's logged best individual for a frame (pose = model in the left camera)."""

    frame: int
    t: float
    found: bool
    fitness: float | None
    generations: int = 0
    rotation: np.ndarray | None = None      # (3, 3)
    position_mm: np.ndarray | None = None   # (3,)
    alpha: float | None = None              # px/mm
    size_mm: np.ndarray | None = None       # (2,)
    T_base_left: np.ndarray | None = None   # (4, 4)

    def T_base_model(self) -> np.ndarray | None:
        """The estimate in the base frame (or the camera frame when no camera pose was logged)."""
        if self.rotation is None or self.position_mm is None:
            return None
        T = make_pose(self.rotation, self.position_mm)
        return T if self.T_base_left is None else self.T_base_left @ T


@dataclass
class TruthRecord:
    frame: int
    t: float
    T_base_target: np.ndarray               # (4, 4)
    size_mm: np.ndarray | None = None


@dataclass
class Series:
    """A time series: t (N,) s and values (N, K)."""

    t: np.ndarray
    values: np.ndarray


@dataclass
class Recording:
    path: Path
    truncated: str | None                   # what is missing when the file was cut short
    setup: Setup
    frames: list[FrameMeta]
    estimates: list[EstimateRecord]
    truth: list[TruthRecord]
    arm: dict[str, Series]                  # "q", "setpoint": (N, 7) rad; "command": rad/s
    timings: dict[str, Series]              # stage -> (N, 1) ms
    events: list[tuple[float, str, str]]    # (t, level, text)
    images: list[Frame] = field(default_factory=list)   # only with read_recording(images=True)


def describe_truncation(rec: Recording) -> str:
    """One line for a truncated recording: what is missing and what was read."""
    ts = [f.t for f in rec.frames]
    span = f" ({ts[0]:.2f}-{ts[-1]:.2f} s)" if ts else ""
    q = rec.arm.get("q")
    arm = f", arm samples to {q.t[-1]:.2f} s" if q is not None and len(q.t) else ""
    return f"{rec.path}: truncated recording: {rec.truncated}; read {len(rec.frames)} frames{span}{arm}"


# ------------------------------------------------------------------------------------------
# the file's chunks


_CUT = re.compile(r"Message payload \(start (\d+), length \d+\) exceeds file size")
_MESSAGE_HEADER = 16   # bytes before each message's payload in an RRD stream
NO_FOOTER = "no RRD footer (the process that wrote it did not close it: killed or crashed)"


class _Chunks:
    """The chunks of one recording as (entity path without the leading '/', record batch).

    A file without its footer is read by rerun's whole-file scan. A file cut inside a message
    (a kill during a write) makes rerun refuse it; it is then read from a copy that ends at the
    last complete message (the payload offset in rerun's error minus the 16-byte message
    header). `truncated` says which happened, after the iteration."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise InputError(f"{self.path}: recording not found")
        self.truncated: str | None = None

    def __iter__(self) -> Iterator[tuple[str, pa.RecordBatch]]:
        path, done, tmp = self.path, 0, None
        try:
            for attempt in range(4):
                try:
                    for i, chunk in enumerate(self._stream(path)):
                        if i >= done:
                            done += 1
                            yield chunk.entity_path.lstrip("/"), chunk.to_record_batch()
                    return
                except RuntimeError as e:
                    m = _CUT.search(str(e))
                    if m is None:
                        raise
                    size = self.path.stat().st_size
                    self.truncated = f"{NO_FOOTER}, cut inside a message at byte {m.group(1)} of {size}"
                    tmp = tmp or tempfile.TemporaryDirectory(prefix="photoservo-salvage-")
                    path = Path(tmp.name) / f"cut{attempt}.rrd"
                    with open(self.path, "rb") as src, open(path, "wb") as dst:
                        _copy_prefix(src, dst, int(m.group(1)) - _MESSAGE_HEADER)
            raise RuntimeError("could not find the last complete message")
        finally:
            if tmp is not None:
                tmp.cleanup()

    def _stream(self, path: Path) -> Iterator[Any]:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            reader = RrdReader(path)
        if any("footer" in str(w.message) for w in caught) and self.truncated is None:
            self.truncated = NO_FOOTER
        return reader.stream()


def _copy_prefix(src: Any, dst: Any, n: int, block: int = 1 << 24) -> None:
    while n > 0:
        data = src.read(min(block, n))
        if not data:
            return
        dst.write(data)
        n -= len(data)


def _times(rb: pa.RecordBatch) -> tuple[np.ndarray | None, np.ndarray | None]:
    names = rb.schema.names
    frame = rb.column("frame").to_numpy(zero_copy_only=False) if "frame" in names else None
    t = (rb.column("time").cast(pa.int64()).to_numpy(zero_copy_only=False) / 1e9
         if "time" in names else None)
    return frame, t


def _cell(rb: pa.RecordBatch, name: str, i: int) -> pa.Array | None:
    """The value array of component `name` at row i (None when absent or null)."""
    if name not in rb.schema.names:
        return None
    v = rb.column(name)[i]
    return v.values if v.is_valid else None


def _num(rb: pa.RecordBatch, name: str, i: int) -> np.ndarray | None:
    v = _cell(rb, name, i)
    return None if v is None else v.to_numpy(zero_copy_only=False)


def _scalar(rb: pa.RecordBatch, name: str, i: int) -> Any:
    v = _cell(rb, name, i)
    return None if v is None or len(v) == 0 else v[0].as_py()


def _blob(rb: pa.RecordBatch, name: str, i: int) -> bytes | None:
    v = _cell(rb, name, i)
    if v is None:
        return None
    if pa.types.is_binary(v.type) or pa.types.is_large_binary(v.type):
        return v[0].as_py()
    return v.flatten().to_numpy(zero_copy_only=False).tobytes()


def _packed(rb: pa.RecordBatch, layout: L.Layout) -> list[dict]:
    """The `values` vectors of a data/ chunk, unpacked by `layout` (see layout.pack)."""
    width = sum(n for _, n in layout)
    flat = rb.column("values").flatten().to_numpy(zero_copy_only=False)
    return [L.unpack(layout, row) for row in flat.reshape(-1, width)]


def _scalar_rows(rb: pa.RecordBatch) -> np.ndarray:
    """The `Scalars:scalars` column of a chunk as an (N, K) array (vectorised: the arm series
    run at the control rate)."""
    col = rb.column("Scalars:scalars")
    if col.null_count == 0 and len(col):
        lengths = pc.list_value_length(col).to_numpy(zero_copy_only=False)
        if np.all(lengths == lengths[0]):
            return col.flatten().to_numpy(zero_copy_only=False).reshape(len(col), int(lengths[0]))
    rows = [_num(rb, "Scalars:scalars", i) for i in range(rb.num_rows)]
    k = max((len(r) for r in rows if r is not None), default=1)
    return np.array([np.full(k, np.nan) if r is None else r for r in rows])


def _decode_image(rb: pa.RecordBatch, i: int) -> np.ndarray:
    blob = _blob(rb, "EncodedImage:blob", i)
    if blob is not None:   # format 1's png and preview modes
        img = cv2.imdecode(np.frombuffer(blob, np.uint8), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise ValueError("undecodable frame in recording")
        return img
    buf = _blob(rb, "Image:buffer", i)
    fmt = _scalar(rb, "Image:format", i)
    if buf is None or fmt is None:
        raise ValueError("frame without image data in recording")
    return np.frombuffer(buf, np.uint8).reshape(fmt["height"], fmt["width"], -1).copy()


def _unpack_model(data: bytes) -> Any:
    """Rebuild the PhotoModel from the npz logged by `Recorder.log_static_setup`."""
    from photoservo.vision.photo_model import PhotoModel
    npz = np.load(io.BytesIO(data))
    kwargs = {}
    for f in dataclasses.fields(PhotoModel):
        if f.name not in npz.files:
            warnings.warn(f"recorded photo-model lacks field '{f.name}' (recorded before it existed); model not "
                          "unpacked (replay rebuilds it from the recorded photo)", stacklevel=3)
            return None
        v = npz[f.name]
        if str(f.type).startswith("tuple"):
            v = tuple(v.tolist())
        kwargs[f.name] = v
    return PhotoModel(**kwargs)


# ------------------------------------------------------------------------------------------
# frames


def _expected_parts(run: dict) -> set[str]:
    """What each frame of a recording carries, from its setup/run: images, planes, video."""
    if run.get("full_frames") or run.get("mode") in ("lossless", "png") or run.get("format", 1) == 1:
        return {"image/left", "image/right"}
    parts = {"video/left", "video/right"} if run.get("video") not in (None, "none") else set()
    return parts | ({"planes"} if run.get("mode") == "compact" else set())


def iter_frames(path: str | Path) -> Iterator[Frame]:
    """Stream the frames of a recording in frame order (`Frame`).

    The parts of a frame (two images, or the planes and two video samples) arrive in separate
    chunks; a frame waits in a small buffer until it has them all and no earlier frame is still
    waiting. At the end of a truncated file, frames that have their images or planes are given
    (a missing video sample then); those without are dropped."""
    from photoservo.record.planes import decode_planes
    from photoservo.record.video import Sample

    pending: dict[int, Frame] = {}
    have: dict[int, set[str]] = {}
    expected: set[str] | None = None
    video_codec = "av1"
    parts = {**{L.E_IMAGE[s]: f"image/{s}" for s in L.SIDES}, **{L.E_VIDEO[s]: f"video/{s}" for s in L.SIDES},
             L.E_PLANES: "planes"}

    def ready(final: bool) -> Iterator[Frame]:
        while pending and expected is not None:
            k = min(pending)
            done = expected <= have[k]
            usable = {"image/left", "image/right"} <= have[k] or "planes" in have[k]
            if not done and not final:
                return
            del have[k]
            fr = pending.pop(k)
            if done or usable:
                yield fr

    for ep, rb in _Chunks(path):
        if ep == L.E_RUN and expected is None:
            run = json.loads(_scalar(rb, "TextDocument:text", rb.num_rows - 1))
            expected, video_codec = _expected_parts(run), run.get("video") or "av1"
        part = parts.get(ep)
        if part is None or "frame" not in rb.schema.names:
            continue
        frame, t = _times(rb)
        for i in range(rb.num_rows):
            k = int(frame[i])
            fr = pending.setdefault(k, Frame(k, float(t[i])))
            kind, _, side = part.partition("/")
            if kind == "image":
                setattr(fr, side, _decode_image(rb, i))
            elif kind == "planes":
                fr.planes = decode_planes(_blob(rb, "planes", i))
            else:
                key = bool(_scalar(rb, "VideoStream:is_keyframe", i))
                fr.video.setdefault(side, []).append(Sample(k, _blob(rb, "VideoStream:sample", i), key, video_codec))
            have.setdefault(k, set()).add(part)
        yield from ready(False)
    yield from ready(True)


# ------------------------------------------------------------------------------------------
# everything else


def read_recording(path: str | Path, *, images: bool = False) -> Recording:
    """Everything but the frames (unless `images=True`) of a recording, as plain data."""
    chunks = _Chunks(path)
    texts: dict[str, str] = {}
    photo = model = None
    frames: dict[int, FrameMeta] = {}
    estimates: dict[int, EstimateRecord] = {}
    truth: dict[int, TruthRecord] = {}
    series: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}   # entity -> (t, values) blocks
    events: list[tuple[float, str, str]] = []
    for ep, rb in chunks:
        frame, t = _times(rb)
        n = rb.num_rows
        if ep in (L.E_RUN, L.E_RIG_TOML, L.E_CONFIG, L.E_WARNING):
            texts[ep] = _scalar(rb, "TextDocument:text", n - 1)  # static: the last one logged holds
        elif ep == L.E_PHOTO and photo is None and "EncodedImage:blob" in rb.schema.names:
            photo = _decode_image(rb, n - 1)
        elif ep == L.E_MODEL and model is None:
            model = _unpack_model(_blob(rb, "npz", n - 1))
        elif ep == L.E_DATA_FRAME:
            for i, v in enumerate(_packed(rb, L.FRAME_LAYOUT)):
                ct, T = v["capture_times"], v["T_base_left"]
                frames[int(frame[i])] = FrameMeta(
                    int(frame[i]), float(t[i]), None if T is None else T.reshape(4, 4),
                    None if ct is None else (float(ct[0]), float(ct[1])))
        elif ep == L.E_DATA_EST:
            for i, v in enumerate(_packed(rb, L.EST_LAYOUT)):
                estimates[int(frame[i])] = _estimate(int(frame[i]), float(t[i]), v)
        elif ep == L.E_DATA_TRUTH:
            for i, v in enumerate(_packed(rb, L.TRUTH_LAYOUT)):
                truth[int(frame[i])] = TruthRecord(int(frame[i]), float(t[i]),
                                                   v["T_base_target"].reshape(4, 4), v["size_mm"])
        elif ep == L.E_EVENTS:
            for i in range(n):
                events.append((float(t[i]), _scalar(rb, "TextLog:level", i) or "",
                               _scalar(rb, "TextLog:text", i)))
        elif ep.startswith(("arm/", "timing/")) and t is not None and "Scalars:scalars" in rb.schema.names:
            series.setdefault(ep, []).append((t, _scalar_rows(rb)))
    if L.E_RUN not in texts:
        why = "cut short before its setup was written" if chunks.truncated else f"no {L.E_RUN}"
        raise InputError(f"{chunks.path}: not a readable photoservo recording ({why})")
    run = json.loads(texts[L.E_RUN])
    setup = Setup(run, texts.get(L.E_RIG_TOML), texts.get(L.E_CONFIG), photo, model, texts.get(L.E_WARNING))
    rec = Recording(chunks.path, chunks.truncated, setup, [frames[k] for k in sorted(frames)],
                    [estimates[k] for k in sorted(estimates)], [truth[k] for k in sorted(truth)],
                    _arm(series), _timings(series), sorted(events, key=lambda e: e[0]))
    if images:
        rec.images = list(iter_frames(path))
    return rec


def _estimate(frame: int, t: float, v: dict) -> EstimateRecord:
    rot, T, a = v["rotation"], v["T_base_left"], v["alpha"]
    return EstimateRecord(frame=frame, t=t, found=bool(v["found"][0]),
                          fitness=None if v["fitness"] is None else float(v["fitness"][0]),
                          generations=int(v["generations"][0]),
                          rotation=None if rot is None else rot.reshape(3, 3),
                          position_mm=v["position_mm"], alpha=None if a is None else float(a[0]),
                          size_mm=v["size_mm"], T_base_left=None if T is None else T.reshape(4, 4))


def _to_series(blocks: list[tuple[np.ndarray, np.ndarray]], scale: float = 1.0) -> Series:
    t = np.concatenate([b[0] for b in blocks])
    v = np.concatenate([b[1] for b in blocks])
    order = np.argsort(t, kind="stable")
    return Series(t[order], v[order] * scale if scale != 1.0 else v[order])


def _arm(series: dict[str, list]) -> dict[str, Series]:
    """The arm series in rad (rad/s), from degrees (format 2) or rad (format 1)."""
    out = {}
    for entity, (key, scale) in {**L.E_ARM, **L.E_ARM_V1}.items():
        if entity in series:
            out[key] = _to_series(series[entity], scale)
    return out


def _timings(series: dict[str, list]) -> dict[str, Series]:
    return {k.split("/", 1)[1].removesuffix("_ms"): _to_series(v)
            for k, v in series.items() if k.startswith("timing/")}
