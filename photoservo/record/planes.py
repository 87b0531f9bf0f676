"""The tracker's input, recorded losslessly and compactly (compact mode, issue 13).

A replay re-runs the tracker, so a recording must give it exactly what it read; it need not
give it the camera frames. Per stereo frame the tracker reads:

  * the fitness input (`vision.fitness.StereoHue`: hue images quantised by the [fitness]
    min_saturation / min_value floors). Every array field of that object is recorded, so a
    plane added to it later is recorded too. The hue planes are reduced to hue CLASSES
    (`hue_class_lut`): two hues that every inner point of the photo-model scores alike
    (d(h, hue_i) <= hue_tolerance for the same i, method step 3) and that are alike target hues
    (`model.target_hues`, outer points and the estimator's blobs) are one class, stored as its
    smallest hue. The fitness, the estimator's seeding blobs, detection and the plane fit's
    target mask read only those tests, so they compute the same numbers on the classes as on
    the hues; water, whose hues are far from the creature's, becomes one value and compresses
    to almost nothing (a 640x480 hue plane: ~105 KB as PNG, its classes ~5 KB). A frame on
    which the estimator would seed from the hue layout (target hues on more than
    estimator.layout_share of the hued pixels: `frame_lut`) keeps its raw hues.
  * grey patches for the stereo plane fit at acquisition (`vision.stereo_plane`, tilt from the
    disparity gradient): left patches (+-4 px, bilinear) around inner points that land on
    target-hue pixels, right patches along their lines of sight (+-8 % depth, +-3 px of
    calibration shift). Recorded: the grey image (cv2 BGR2GRAY) within GREY_RADIUS_PX of a
    target-hue pixel, 0 elsewhere. Left is exact by construction (radius 6 > 5 px); right
    is exact while the candidate's points land within 32 px of target hue in the right image
    (any candidate the GA converged on in both images); `benchmarks/recording.py` measures
    replay fidelity against full frames.

The classes depend on the photo-model and [fitness] hue_tolerance (and the hue images on
min_saturation / min_value): a replay of a compact recording cannot change those keys
(`HUE_KEYS`, photo_model.*), and says so; tracker, GA, estimator, fitness weights and servo
keys replay exactly. Planes are PNG-compressed (lossless) into one npz blob.
"""

from __future__ import annotations

import dataclasses
import io
import zlib
from typing import Any

import cv2
import numpy as np

from photoservo.vision.photo_model import HUE_BINS, hue_distance, target_hue_lut

#: Keys the hue planes depend on; with photo_model.* they need full frames to change.
#: estimator.layout_share decides which frames keep their raw hues (`frame_lut`).
HUE_KEYS = ("fitness.hue_tolerance", "fitness.min_saturation", "fitness.min_value", "estimator.layout_share")
HUE_FIELDS = ("left", "right")          # the hue planes of the fitness input (StereoHue)
GREY_RADIUS_PX = {"left": 6, "right": 32}
FITNESS, GREY = "fitness/", "grey/"     # plane-name prefixes
#: PNG settings (zlib RLE strategy; hue classes without the prediction filter, which only
#: helps smooth images): the smallest and cheapest of those tried on simulator frames, 3.3 KB
#: per hue-class plane, 7 / 14 KB per left / right grey plane (benchmarks/recording.py)
PNG_LABELS = [cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE, cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE]
PNG_IMAGES = [cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE, cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_SUB]


def hue_class_lut(inner_hue: np.ndarray, target_hues: np.ndarray, hue_tolerance: int) -> np.ndarray:
    """(256,) uint8 map hue -> its class representative (module docstring): the smallest hue
    h' with the same tests d(h', hue_i) <= tol for every distinct inner hue hue_i, and the same
    target_hues[h']. Values >= HUE_BINS (NO_HUE) map to themselves."""
    lut = np.arange(256, dtype=np.uint8)
    h = np.arange(HUE_BINS)
    inner = np.unique(np.asarray(inner_hue, dtype=np.int16))
    tests = np.concatenate([hue_distance(h[:, None], inner[None, :]) <= hue_tolerance,
                            np.asarray(target_hues, bool).reshape(HUE_BINS, 1)], axis=1)
    first: dict[bytes, int] = {}
    for v in range(HUE_BINS):
        lut[v] = first.setdefault(np.packbits(tests[v]).tobytes(), v)
    return lut


def frame_lut(lut: np.ndarray | None, hue_left: np.ndarray, target_hues: np.ndarray | None,
              layout_share: float) -> np.ndarray | None:
    """The class map for one frame, or None (keep the raw hues) when the estimator would seed
    from the hue layout (`vision/hue_layout.py`, more than `layout_share` of the left image's
    hued pixels in target hues): that path reads hue values, not only the class tests."""
    if lut is None or target_hues is None:
        return lut
    counts = hue_histogram(hue_left)
    hued = counts.sum()
    share = counts[np.asarray(target_hues, bool)].sum() / hued if hued else 0.0
    return None if share > layout_share else lut


def hue_histogram(hue: np.ndarray) -> np.ndarray:
    """(HUE_BINS,) pixel count per hue value of a uint8 hue image (NO_HUE pixels left out)."""
    counts = cv2.calcHist([np.ascontiguousarray(hue, np.uint8)], [0], None, [256], [0, 256])
    return counts.reshape(-1)[:HUE_BINS].astype(np.int64)


def apply_lut(image: np.ndarray, lut: np.ndarray) -> np.ndarray:
    """lut[image] for a uint8 image and a (256,) uint8 table, through cv2.LUT (~10x numpy's
    fancy indexing on a 640x480 plane: this runs twice per recorded frame)."""
    return cv2.LUT(np.ascontiguousarray(image, np.uint8), np.ascontiguousarray(lut, np.uint8))


def target_mask(hue: np.ndarray, target_hues: np.ndarray) -> np.ndarray:
    """uint8 (H, W): 1 where the hue image has one of the model's target hues."""
    return apply_lut(hue, target_hue_lut(target_hues).astype(np.uint8))


def grey_near_target(bgr: np.ndarray, hue: np.ndarray, target_hues: np.ndarray | None,
                     radius: int) -> np.ndarray:
    """The grey image of a BGR frame within `radius` px (square) of a target-hue pixel, 0 away
    from them; the whole grey image when target_hues is None (no photo-model known)."""
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    if target_hues is None:
        return grey
    near = cv2.dilate(target_mask(hue, target_hues), np.ones((2 * radius + 1,) * 2, np.uint8))
    return grey * near


def tracker_planes(fitness_input: Any, left_bgr: np.ndarray, right_bgr: np.ndarray,
                   lut: np.ndarray | None, target_hues: np.ndarray | None) -> dict[str, np.ndarray]:
    """Every plane the tracker reads (module docstring), by name: `fitness/<field>` for each
    array field of the fitness input (hue fields through `lut` when given; a field left None is
    not recorded), `grey/left|right`."""
    planes = {}
    for f in dataclasses.fields(fitness_input):
        if getattr(fitness_input, f.name) is None:  # an optional plane not in use (StereoHue.chroma)
            continue
        a = np.asarray(getattr(fitness_input, f.name))
        hue_plane = lut is not None and f.name in HUE_FIELDS and a.dtype == np.uint8
        planes[FITNESS + f.name] = apply_lut(a, lut) if hue_plane else a
    for side, bgr in (("left", left_bgr), ("right", right_bgr)):
        hue = getattr(fitness_input, side)
        planes[GREY + side] = grey_near_target(bgr, hue, target_hues, GREY_RADIUS_PX[side])
    return planes


def encode_planes(planes: dict[str, np.ndarray]) -> bytes:
    """Planes as one npz blob: 2-D uint8/uint16 planes as PNG, others as zlib'd .npy (lossless).
    A grey plane is stored cropped to the rectangle around its non-zero pixels (it is 0 away
    from the target: a fifth of the PNG time and size), named `<name>@<H>x<W>+<y>+<x>.png`."""
    entries = {}
    for name, a in planes.items():
        if a.ndim == 2 and a.dtype in (np.uint8, np.uint16):
            key = name
            if name.startswith(GREY) and a.dtype == np.uint8:
                x, y, w, h = cv2.boundingRect(a) if a.any() else (0, 0, 1, 1)
                key = f"{name}@{a.shape[0]}x{a.shape[1]}+{y}+{x}"
                a = a[y:y + h, x:x + w]
            ok, buf = cv2.imencode(".png", a, PNG_LABELS if name.startswith(FITNESS) else PNG_IMAGES)
            if not ok:
                raise RuntimeError(f"cannot encode plane {name} as PNG")
            entries[f"{key}.png"] = buf.reshape(-1)
        else:
            raw = io.BytesIO()
            np.save(raw, a, allow_pickle=False)
            entries[f"{name}.npy.z"] = np.frombuffer(zlib.compress(raw.getvalue(), 3), np.uint8)
    out = io.BytesIO()
    np.savez(out, **entries)
    return out.getvalue()


def decode_planes(data: bytes) -> dict[str, np.ndarray]:
    """Inverse of `encode_planes`."""
    planes = {}
    with np.load(io.BytesIO(data), allow_pickle=False) as npz:
        for key in npz.files:
            blob = npz[key]
            if key.endswith(".png"):
                a = cv2.imdecode(blob, cv2.IMREAD_UNCHANGED)
                if a is None:
                    raise ValueError(f"undecodable plane {key}")
                name, _, box = key.removesuffix(".png").partition("@")
                planes[name] = _uncrop(a, box) if box else a
            else:
                planes[key.removesuffix(".npy.z")] = np.load(io.BytesIO(zlib.decompress(blob.tobytes())),
                                                             allow_pickle=False)
    return planes


def _uncrop(a: np.ndarray, box: str) -> np.ndarray:
    """A cropped plane (`encode_planes`, box "<H>x<W>+<y>+<x>") back in its full size, 0 around."""
    size, y, x = box.split("+")
    H, W = (int(v) for v in size.split("x"))
    full = np.zeros((H, W), a.dtype)
    full[int(y):int(y) + a.shape[0], int(x):int(x) + a.shape[1]] = a
    return full


def tracker_input(planes: dict[str, np.ndarray], input_type: type) -> tuple[Any, np.ndarray, np.ndarray]:
    """(fitness input of `input_type`, left BGR, right BGR) rebuilt from recorded planes for a
    replay: the BGR frames are the recorded grey planes in all three channels, whose grey
    (cv2 BGR2GRAY) is that plane exactly. KeyError names a plane the recording lacks (one
    `input_type` gained after the recording was made)."""
    fields = {}
    for f in dataclasses.fields(input_type):
        if FITNESS + f.name not in planes:
            if f.default is None:  # an optional plane the recording did not carry
                continue
            raise KeyError(f"fitness input plane '{f.name}'")
        fields[f.name] = np.ascontiguousarray(planes[FITNESS + f.name])
    bgr = [cv2.merge([planes[GREY + s]] * 3) for s in ("left", "right")]
    return input_type(**fields), bgr[0], bgr[1]
