"""Reading recordings back (issue 6, the reading side of replay) and comparing two runs.

`read_recording(path)` reads a `.rrd` written by `record.recorder.Recorder` — one file, or all
segments `<stem>.seg0001.rrd ...` of a segmented recording as one — with
`rerun.chunk.RrdReader` (rerun-sdk 0.41; `rerun.dataframe` no longer exists) into plain
dataclasses: the static setup (rig TOML, effective config TOML, photo, PhotoModel, seed,
versions), the per-frame metadata, estimates, ground truth, arm series, timings and events.
`iter_frames(path)` streams the stereo images in frame order, decoded exactly as logged (PNG /
raw are bit-exact); `read_recording(path, images=True)` loads them all (short recordings).

A segment without its RRD footer (the one being written when the process was killed) is read
as far as its complete chunks go and listed in `Recording.incomplete`.

`compare_runs(a, b)` builds the side-by-side table replay prints: mean fitness, found ratio,
pose jitter, lost frames, time per frame, commanded motion and, when both runs carry the
simulator's ground truth, position / heading / tilt / size error. Definitions at `run_metrics`.
"""

from __future__ import annotations

import dataclasses
import glob
import io
import json
import math
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
from photoservo.geometry import make_pose
from photoservo.record import recorder as R_

_SEG = re.compile(r"^(?P<stem>.*)\.seg(?P<n>\d{4,})(?P<partial>\.partial)?$")


# ------------------------------------------------------------------------------------------
# dataclasses


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


@dataclass
class FrameMeta:
    """One logged stereo frame without its pixels: loop time t (s), where the left camera was."""

    index: int
    t: float
    T_base_left: np.ndarray | None = None
    capture_times: tuple[float, float] | None = None


@dataclass
class Frame:
    """One stereo frame read back: BGR uint8 images exactly as logged (lossless modes)."""

    index: int
    t: float
    left: np.ndarray
    right: np.ndarray


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
    files: list[Path]
    incomplete: list[Path]
    setup: Setup
    frames: list[FrameMeta]
    estimates: list[EstimateRecord]
    truth: list[TruthRecord]
    arm: dict[str, Series]                  # "q", "setpoint", "command": (N, 7) rad
    timings: dict[str, Series]              # stage -> (N, 1) ms
    events: list[tuple[float, str, str]]    # (t, level, text)
    images: list[Frame] = field(default_factory=list)   # only with read_recording(images=True)


# ------------------------------------------------------------------------------------------
# files and chunks


def recording_files(path: str | Path) -> list[Path]:
    """The files of a recording: `path` itself, or its segments in order (finished
    `.segNNNN.rrd` and the `.segNNNN.partial.rrd` tail a hard kill leaves). `path` may be the
    base path (`x.rrd`) or any one segment (`x.seg0003.rrd`)."""
    p = Path(path)
    m = _SEG.match(p.stem)
    base = p.with_name(m["stem"] + p.suffix) if m else p
    if p.is_file() and not m:
        return [p]
    found = [(int(mm["n"]), s) for s in base.parent.glob(f"{glob.escape(base.stem)}.seg*{base.suffix}")
             if (mm := _SEG.match(s.stem)) and mm["stem"] == base.stem]
    if not found:
        raise InputError(f"{p}: recording not found (no such file, no {base.stem}.seg*.rrd)")
    return [s for _, s in sorted(found)]


def _open(path: Path) -> tuple[RrdReader, bool]:
    """(reader, complete): a file without its RRD footer was cut short (hard kill)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        reader = RrdReader(path)
    complete = not any("footer" in str(w.message) for w in caught)
    return reader, complete


_CUT = re.compile(r"Message payload \(start (\d+), length \d+\) exceeds file size")
_MESSAGE_HEADER = 16   # bytes before each message's payload in an RRD stream


def _file_chunks(f: Path, incomplete: list[Path]) -> Iterator[tuple[str, pa.RecordBatch]]:
    """The chunks of one file. A file cut inside a message (a hard kill during a write) makes
    rerun refuse the whole file; it is then read from a copy that ends at the last complete
    message (the payload offset in rerun's error minus the 16-byte message header)."""
    path, done, tmp = f, 0, None
    try:
        for _ in range(4):
            try:
                reader, complete = _open(path)
                if (not complete or f.stem.endswith(".partial")) and f not in incomplete:
                    incomplete.append(f)
                for i, chunk in enumerate(reader.stream()):
                    if i >= done:
                        done += 1
                        yield chunk.entity_path.lstrip("/"), chunk.to_record_batch()
                return
            except RuntimeError as e:
                m = _CUT.search(str(e))
                if m is None:
                    raise
                if f not in incomplete:
                    incomplete.append(f)
                if tmp is None:
                    tmp = tempfile.TemporaryDirectory(prefix="photoservo-salvage-")
                cut = Path(tmp.name) / f"cut{_}.rrd"
                with open(f, "rb") as src, open(cut, "wb") as dst:
                    _copy_prefix(src, dst, int(m.group(1)) - _MESSAGE_HEADER)
                path = cut
        raise RuntimeError("could not find the last complete message")
    finally:
        if tmp is not None:
            tmp.cleanup()


def _copy_prefix(src: Any, dst: Any, n: int, block: int = 1 << 24) -> None:
    while n > 0:
        data = src.read(min(block, n))
        if not data:
            return
        dst.write(data)
        n -= len(data)


def _chunks(files: list[Path], incomplete: list[Path]) -> Iterator[tuple[str, pa.RecordBatch]]:
    """(entity path without the leading '/', record batch) of every chunk, file by file; a
    file that cannot be read to its end is listed in `incomplete` with a warning."""
    for f in files:
        try:
            yield from _file_chunks(f, incomplete)
        except (OSError, ValueError, RuntimeError) as e:
            if f not in incomplete:
                incomplete.append(f)
            warnings.warn(f"{f}: read stopped early ({e})", stacklevel=2)


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


def _packed(rb: pa.RecordBatch, layout: tuple[tuple[str, int], ...]) -> list[dict]:
    """The `values` vectors of a data/ chunk, unpacked by `layout` (see recording.pack)."""
    width = sum(n for _, n in layout)
    flat = rb.column("values").flatten().to_numpy(zero_copy_only=False)
    return [R_.unpack(layout, row) for row in flat.reshape(-1, width)]


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
    if blob is not None:
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
            warnings.warn(f"recorded photo-model lacks field '{f.name}'; model not rebuilt", stacklevel=3)
            return None
        v = npz[f.name]
        if str(f.type).startswith("tuple"):
            v = tuple(v.tolist())
        kwargs[f.name] = v
    return PhotoModel(**kwargs)


# ------------------------------------------------------------------------------------------
# readers


def iter_frames(path: str | Path) -> Iterator[Frame]:
    """Stream the stereo frames of a recording in frame order, decoded (BGR uint8).

    Left and right arrive in separate chunks; encoded pairs wait in a small buffer and are
    decoded when complete and no earlier frame is still missing a side. A frame with only
    one side (cut by a hard kill) is dropped at the end."""
    pending: dict[int, dict[str, Any]] = {}
    entities = {R_.E_IMAGE["left"]: "left", R_.E_IMAGE["right"]: "right"}

    def ready() -> Iterator[Frame]:
        while pending:
            k = min(pending)
            entry = pending[k]
            if "left" not in entry or "right" not in entry:
                return
            del pending[k]
            yield Frame(k, entry["t"], _decode_image(*entry["left"]), _decode_image(*entry["right"]))

    for ep, rb in _chunks(recording_files(path), []):
        side = entities.get(ep)
        if side is None:
            continue
        frame, t = _times(rb)
        for i in range(rb.num_rows):
            entry = pending.setdefault(int(frame[i]), {"t": float(t[i])})
            entry[side] = (rb, i)
        yield from ready()
    yield from ready()


def read_recording(path: str | Path, *, images: bool = False) -> Recording:
    """Everything but the images (unless `images=True`) of a recording, as plain data."""
    files = recording_files(path)
    incomplete: list[Path] = []
    run: dict = {}
    texts: dict[str, str] = {}
    photo = model = None
    frames: dict[int, FrameMeta] = {}
    estimates: dict[int, EstimateRecord] = {}
    truth: dict[int, TruthRecord] = {}
    series: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}   # entity -> (t, values) blocks
    events: list[tuple[float, str, str]] = []
    for ep, rb in _chunks(files, incomplete):
        frame, t = _times(rb)
        n = rb.num_rows
        if ep in (R_.E_RUN, R_.E_RIG_TOML, R_.E_CONFIG, R_.E_WARNING):
            if ep not in texts:
                texts[ep] = _scalar(rb, "TextDocument:text", n - 1)
        elif ep == R_.E_PHOTO and photo is None and "EncodedImage:blob" in rb.schema.names:
            photo = _decode_image(rb, n - 1)
        elif ep == R_.E_MODEL and model is None:
            model = _unpack_model(_blob(rb, "npz", n - 1))
        elif ep == R_.E_DATA_FRAME:
            for i, v in enumerate(_packed(rb, R_.FRAME_LAYOUT)):
                ct, T = v["capture_times"], v["T_base_left"]
                frames[int(frame[i])] = FrameMeta(
                    int(frame[i]), float(t[i]), None if T is None else T.reshape(4, 4),
                    None if ct is None else (float(ct[0]), float(ct[1])))
        elif ep == R_.E_DATA_EST:
            for i, v in enumerate(_packed(rb, R_.EST_LAYOUT)):
                rot, T, a = v["rotation"], v["T_base_left"], v["alpha"]
                estimates[int(frame[i])] = EstimateRecord(
                    frame=int(frame[i]), t=float(t[i]), found=bool(v["found"][0]),
                    fitness=None if v["fitness"] is None else float(v["fitness"][0]),
                    generations=int(v["generations"][0]),
                    rotation=None if rot is None else rot.reshape(3, 3),
                    position_mm=v["position_mm"], alpha=None if a is None else float(a[0]),
                    size_mm=v["size_mm"], T_base_left=None if T is None else T.reshape(4, 4))
        elif ep == R_.E_DATA_TRUTH:
            for i, v in enumerate(_packed(rb, R_.TRUTH_LAYOUT)):
                truth[int(frame[i])] = TruthRecord(int(frame[i]), float(t[i]),
                                                   v["T_base_target"].reshape(4, 4), v["size_mm"])
        elif ep == R_.E_EVENTS:
            for i in range(n):
                events.append((float(t[i]), _scalar(rb, "TextLog:level", i) or "",
                               _scalar(rb, "TextLog:text", i)))
        elif ep.startswith(("arm/", "timing/")) and t is not None \
                and "Scalars:scalars" in rb.schema.names:
            series.setdefault(ep, []).append((t, _scalar_rows(rb)))
    if R_.E_RUN not in texts:
        why = "cut short before its setup was written" if incomplete else f"no {R_.E_RUN}"
        raise InputError(f"{files[0]}: not a readable photoservo recording ({why})")

    def to_series(blocks: list[tuple[np.ndarray, np.ndarray]]) -> Series:
        t = np.concatenate([b[0] for b in blocks])
        v = np.concatenate([b[1] for b in blocks])
        order = np.argsort(t, kind="stable")
        return Series(t[order], v[order])

    arm = {k.split("/", 1)[1]: to_series(v) for k, v in series.items() if k.startswith("arm/")}
    timings = {k.split("/", 1)[1].removesuffix("_ms"): to_series(v)
               for k, v in series.items() if k.startswith("timing/")}
    run = json.loads(texts[R_.E_RUN])
    setup = Setup(run, texts.get(R_.E_RIG_TOML), texts.get(R_.E_CONFIG), photo, model,
                  texts.get(R_.E_WARNING))
    rec = Recording(files, incomplete, setup, [frames[k] for k in sorted(frames)],
                    [estimates[k] for k in sorted(estimates)], [truth[k] for k in sorted(truth)],
                    arm, timings, sorted(events, key=lambda e: e[0]))
    if images:
        rec.images = list(iter_frames(path))
    return rec


# ------------------------------------------------------------------------------------------
# comparing two runs


def _heading_tilt(T: np.ndarray) -> tuple[float, float]:
    """Heading: direction of the model x axis in the base xy plane (rad). Tilt: angle of the
    model z axis from the base vertical (rad, 0..pi/2, sign of z ignored)."""
    x, z = T[:3, 0], T[:3, 2]
    return math.atan2(x[1], x[0]), math.acos(min(1.0, abs(float(z[2]) / np.linalg.norm(z))))


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def run_metrics(rec: Recording) -> dict[str, float]:
    """Per-run numbers of the comparison table (NaN when a run lacks the data):

    frames            frames logged
    mean_fitness      mean fitness over all estimates that have one
    found_ratio       estimates with found / estimates
    lost_frames       estimates with found = false
    jitter_mm         RMS of the second difference |p[k+1] - 2 p[k] + p[k-1]| of the estimated
                      position (base frame when the camera pose was logged) over consecutive
                      found frames: shake that a constant-velocity drift does not contribute
    ms_per_frame      (t_last - t_first) / (frames - 1) * 1000 on the loop clock
    tracker_ms        mean hue + mean GA time per frame (timing/hue_ms, timing/ga_ms): the
                      processing cost, which a replay changes while its frame times do not
    commanded_rad     joint-space path length of the commands, sum_k ||c[k] - c[k-1]||_2
    pos_err_mm        RMS ||p_est - p_true|| (base frame) over found frames with truth
    heading_err_deg   RMS heading difference (model x axis in the base xy plane, wrapped)
    tilt_err_deg      RMS difference of tilt (model z axis from the vertical)
    size_err_mm       RMS over found frames of the mean |size_est - size_true| of the 2 sides
    hold_err_mm       servo: RMS over frames with truth and a camera pose of the distance from
                      the rig's centre (midpoint of the optical centres, from T_base_left and the
                      recorded rig) to where the servo law wants it, [servo] hover_mm straight
                      above the TRUE target; all frames, the approach included
    """
    nan = float("nan")
    est = rec.estimates
    found = [e for e in est if e.found and e.T_base_model() is not None]
    m: dict[str, float] = {"frames": float(len(rec.frames))}
    fits = [e.fitness for e in est if e.fitness is not None]
    m["mean_fitness"] = float(np.mean(fits)) if fits else nan
    m["found_ratio"] = len([e for e in est if e.found]) / len(est) if est else nan
    m["lost_frames"] = float(len([e for e in est if not e.found])) if est else nan
    d2 = []
    for a, b, c in zip(found, found[1:], found[2:]):
        if b.frame == a.frame + 1 and c.frame == b.frame + 1:
            pa_, pb, pc = (e.T_base_model()[:3, 3] for e in (a, b, c))
            d2.append(float(np.linalg.norm(pc - 2 * pb + pa_)))
    m["jitter_mm"] = float(np.sqrt(np.mean(np.square(d2)))) if d2 else nan
    ts = [f.t for f in rec.frames]
    m["ms_per_frame"] = (ts[-1] - ts[0]) / (len(ts) - 1) * 1000 if len(ts) > 1 else nan
    if "hue" in rec.timings and "ga" in rec.timings:
        m["tracker_ms"] = float(np.mean(rec.timings["hue"].values) + np.mean(rec.timings["ga"].values))
    else:
        m["tracker_ms"] = nan
    cmd = rec.arm.get("command")
    m["commanded_rad"] = (float(np.linalg.norm(np.diff(cmd.values, axis=0), axis=1).sum())
                          if cmd is not None and len(cmd.t) > 1 else nan)
    truth = {tr.frame: tr for tr in rec.truth}
    pos, head, tilt, size = [], [], [], []
    for e in found:
        tr = truth.get(e.frame)
        if tr is None:
            continue
        Te, Tt = e.T_base_model(), tr.T_base_target
        pos.append(float(np.linalg.norm(Te[:3, 3] - Tt[:3, 3])))
        (he, te), (ht, tt) = _heading_tilt(Te), _heading_tilt(Tt)
        head.append(_wrap(he - ht))
        tilt.append(te - tt)
        if e.size_mm is not None and tr.size_mm is not None:
            size.append(float(np.mean(np.abs(e.size_mm - tr.size_mm))))

    def rms(v: list[float], scale: float = 1.0) -> float:
        return float(np.sqrt(np.mean(np.square(v)))) * scale if v else nan
    m["pos_err_mm"] = rms(pos)
    m["heading_err_deg"] = rms(head, 180 / math.pi)
    m["tilt_err_deg"] = rms(tilt, 180 / math.pi)
    m["size_err_mm"] = rms(size)
    m["hold_err_mm"] = rms(_hold_errors(rec, truth))
    return m


def _hold_errors(rec: Recording, truth: dict[int, TruthRecord]) -> list[float]:
    """Per frame |rig centre - (true target + hover_mm up)| (mm), see run_metrics."""
    import tomllib
    try:
        rig = rec.setup.rig()
        hover = float(tomllib.loads(rec.setup.config_toml or "")["servo"]["hover_mm"])
    except (KeyError, TypeError, ValueError, InputError):
        return []
    if rig is None:
        return []
    from photoservo.servo.session import left_centre
    centre = left_centre(rig)
    out = []
    for f in rec.frames:
        tr = truth.get(f.index)
        if tr is None or f.T_base_left is None:
            continue
        c = f.T_base_left[:3, :3] @ centre + f.T_base_left[:3, 3]
        out.append(float(np.linalg.norm(c - tr.T_base_target[:3, 3] - np.array([0.0, 0.0, hover]))))
    return out


METRICS: tuple[tuple[str, str, str], ...] = (
    ("frames", "frames", "{:.0f}"),
    ("mean_fitness", "mean fitness", "{:.4f}"),
    ("found_ratio", "found ratio", "{:.3f}"),
    ("lost_frames", "lost frames", "{:.0f}"),
    ("jitter_mm", "pose jitter (mm)", "{:.2f}"),
    ("ms_per_frame", "time per frame (ms)", "{:.1f}"),
    ("tracker_ms", "tracker ms per frame", "{:.1f}"),
    ("commanded_rad", "commanded motion (rad)", "{:.3f}"),
    ("pos_err_mm", "position error (mm RMS)", "{:.2f}"),
    ("heading_err_deg", "heading error (deg RMS)", "{:.2f}"),
    ("tilt_err_deg", "tilt error (deg RMS)", "{:.2f}"),
    ("size_err_mm", "size error (mm RMS)", "{:.2f}"),
    ("hold_err_mm", "hold error vs truth (mm RMS)", "{:.1f}"),
)


@dataclass
class ComparisonRow:
    key: str
    label: str
    a: float
    b: float

    @property
    def delta(self) -> float:
        return self.b - self.a


@dataclass
class Comparison:
    """Side-by-side numbers of two runs; `str()` is the table replay prints."""

    name_a: str
    name_b: str
    rows: list[ComparisonRow]

    def row(self, key: str) -> ComparisonRow:
        return next(r for r in self.rows if r.key == key)

    def __str__(self) -> str:
        fmt = {k: f for k, _, f in METRICS}

        def cell(v: float, key: str) -> str:
            return "-" if math.isnan(v) else fmt[key].format(v)
        head = ("", self.name_a, self.name_b, "B - A")
        body = [(r.label, cell(r.a, r.key), cell(r.b, r.key), cell(r.delta, r.key)) for r in self.rows]
        w = [max(len(x[i]) for x in [head, *body]) for i in range(4)]
        line = lambda x: "  ".join([x[0].ljust(w[0])] + [x[i].rjust(w[i]) for i in (1, 2, 3)])
        return "\n".join([line(head), "  ".join("-" * n for n in w), *map(line, body)])


def compare_runs(a: Recording | str | Path, b: Recording | str | Path, name_a: str = "A",
                 name_b: str = "B") -> Comparison:
    """The comparison table of two runs (replay vs recorded, or two closed-loop runs), given
    as recordings read or as paths. Truth rows are NaN ('-') unless the runs carry truth."""
    a, b = (r if isinstance(r, Recording) else read_recording(r) for r in (a, b))
    ma, mb = run_metrics(a), run_metrics(b)
    return Comparison(name_a, name_b, [ComparisonRow(k, lbl, ma[k], mb[k]) for k, lbl, _ in METRICS])
