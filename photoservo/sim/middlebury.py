"""Real, calibrated stereo pairs with ground truth, standing in for the cameras (`PAIRS`):

- "motorcycle": Middlebury 2014 "Motorcycle" as scikit-image ships it
  (`skimage.data.stereo_motorcycle()`: left and right images, 741 x 500 px, rectified, and the
  ground-truth disparity of the left image). Middlebury's calib.txt for Motorcycle at full
  resolution: f = 3979.911 px, cx0 = 1244.772, cx1 = 1369.115, cy = 1019.507 px,
  doffs = cx1 - cx0 = 124.343 px, baseline = 193.001 mm; scikit-image downsampled the images by 4
  with `downscale_local_mean` and quotes these numbers divided by 4: f = 994.978 px,
  cx0 = 311.193, cy = 254.877, doffs = 31.086 px, baseline 193.001 mm. A 4x area downsampling
  moves a pixel centre c to (c + 0.5) / 4 - 0.5 = c / 4 - 0.375: both principal points get that
  shift here.
- "aloe": Middlebury 2006 "Aloe" at full size as Debian's `opencv-doc` package ships it
  (usr/share/doc/opencv-doc/examples/data/aloeL.jpg, aloeR.jpg: views 1 and 5, 1282 x 1110 px,
  JPEG; aloeGT.png: the left view's disparity in px, 0 = unknown). Not in the CI: see
  `aloe_pair` for where it is looked for. Middlebury's 2005/2006 calibration is one number set
  for all scenes at full size: f = 3740 px, baseline 160 mm (views 1 and 5); a scene's disparity
  offset dmin (its dmin.txt, not shipped by Debian) plays the part of doffs: Z = f · B / (d + dmin).
  ASSUMED here: dmin = 270 px (`ALOE_DMIN_PX`), and the principal point at the image centre (the
  2006 data give none). Percent errors of depth and size hardly depend on them (rig and truth use
  the same numbers); millimetres do (dmin 200 instead of 270 puts the pot 1.92 m away, not 1.57 m).

Depth from the left image's disparity d (Middlebury: x_right = x_left - d):
Z = baseline · f / (d + doffs) mm. As an OpenCV rig: two pinhole cameras without distortion,
the right one's principal point at cx0 + doffs, R = I, T = (-baseline, 0, 0) mm.

Targets (`Target`, each pair's `targets`; `TARGETS`: the motorcycle's boxes): each given by a box in
the left image. The motorcycle's are smooth red parts of distinct shapes; a target's region is the
red part inside the box (`red_region`: largest connected region of red hue, holes filled). The
aloe's are the terracotta pot, a single long leaf and an upright leaf; a target's region is the
surface grown from a seed pixel over the ground-truth disparity inside the box (`surface_region`:
neighbours within 1 px of disparity), for the pot only where the hue is the pot's. For each target, three photo variants the estimator may be given (`real_cases`): the
target cut from the left image, cut from the right image (its region found the same way in the
box moved by the target's median disparity), and the left cut resized (another scale). A cut is
the target's region on a plain grey backdrop (as one would cut an object out of a photo), so the
photo-model comes from the default border-inward scan; GrabCut (`--roi`) on the uncut crop
gives masks that also take in the fork or the wall behind, which would blur what is measured.

Ground truth of a case, for the photo-model built from its photo, in the left camera frame
(the estimate JSON shape): the target's depth Z is the median depth over the model's own mask
seen in the camera the photo came from (the right image's disparity is the left one
forward-warped, nearest surface kept); position_mm is the ray through the model origin's pixel
at that depth; rotation = I (the photo faces the camera it was cut from; R_stereo = I);
alpha = k · f / Z for a photo at k image px per photo px; size_mm = size_px / alpha. Extra
keys: target, variant, scale, box_px (the target's box in the left image, for the "right
object" test), depth_spread_mm (10th and 90th percentile of the depth over the model's mask).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.vision.photo_model import PhotoModel, PhotoModelParams, build_photo_model
from photoservo.vision.rig import Camera, Rig

# scikit-image's numbers for the 4x downsampled pair (Middlebury calib.txt / 4), see above
F_PX = 994.978
CX0_PX = 311.193 - 0.375
CY_PX = 254.877 - 0.375
DOFFS_PX = 31.086
BASELINE_MM = 193.001

# Middlebury 2005/2006 at full size (module docstring); dmin and the principal point assumed
ALOE_F_PX = 3740.0
ALOE_BASELINE_MM = 160.0
ALOE_DMIN_PX = 270.0
ALOE_SIZE = (1282, 1110)
ALOE_ENV = "PHOTOSERVO_ALOE_DIR"  # a folder holding aloeL.jpg, aloeR.jpg, aloeGT.png
ALOE_DEFAULT_DIR = "/usr/share/doc/opencv-doc/examples/data"
ALOE_FILES = ("aloeL.jpg", "aloeR.jpg", "aloeGT.png")


@dataclass(frozen=True)
class Target:
    """A target of a pair: its box (x, y, w, h) in the full-size left image; with `seed` (a pixel on
    it, full-size left image) its region is the surface grown from the seed (`surface_region`),
    kept where the hue is within `hues` (OpenCV hue lo..hi, saturation >= s_min) when given;
    without, the red region in the box (`red_region`)."""

    box: tuple[int, int, int, int]
    seed: tuple[int, int] | None = None
    hues: tuple[int, int, int] | None = None


@dataclass(frozen=True)
class StereoPair:
    """A rectified pair with ground truth: `load()` gives (left BGR, right BGR, left disparity
    float32 px, NaN where unknown) at the size the calibration is for (module docstring)."""

    name: str
    title: str
    size: tuple[int, int]
    f_px: float
    cx0_px: float
    cy_px: float
    doffs_px: float
    baseline_mm: float
    targets: dict[str, Target]
    load: Callable[[], tuple[np.ndarray, np.ndarray, np.ndarray]]
    default_scale: float = 1.0


def _motorcycle_full() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    try:
        from skimage import data
    except ImportError:
        raise InputError("the Middlebury pair needs scikit-image: pip install 'photoservo[test]'") from None
    left, right, disp = data.stereo_motorcycle()
    left = np.ascontiguousarray(left[..., ::-1])
    right = np.ascontiguousarray(right[..., ::-1])
    disp = np.where(np.isfinite(disp), disp, np.nan).astype(np.float32)
    return left, right, disp


def aloe_dir() -> Path:
    """The folder holding the aloe pair: $PHOTOSERVO_ALOE_DIR, else Debian's opencv-doc folder."""
    return Path(os.environ.get(ALOE_ENV) or ALOE_DEFAULT_DIR)


def aloe_missing() -> str | None:
    """None when the aloe pair's files are there, else a one-line message naming the missing
    file and how to get it."""
    folder = aloe_dir()
    for name in ALOE_FILES:
        if not (folder / name).is_file():
            return (f"the aloe pair needs {folder / name}: `apt-get install opencv-doc`, or `apt-get download "
                    f"opencv-doc && dpkg-deb -x opencv-doc_*.deb DIR` and {ALOE_ENV}="
                    f"DIR/usr/share/doc/opencv-doc/examples/data")
    return None


def _aloe_full() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    missing = aloe_missing()
    if missing:
        raise InputError(missing)
    folder = aloe_dir()
    left, right = (cv2.imread(str(folder / n), cv2.IMREAD_COLOR) for n in ALOE_FILES[:2])
    gt = cv2.imread(str(folder / ALOE_FILES[2]), cv2.IMREAD_UNCHANGED)
    if left is None or right is None or gt is None or gt.ndim != 2:
        raise InputError(f"the aloe pair in {folder} is unreadable (expected two colour JPEGs and a grey PNG)")
    disp = np.where(gt > 0, gt, np.nan).astype(np.float32)
    return left, right, disp


MOTORCYCLE = StereoPair(
    "motorcycle", "Middlebury 2014 Motorcycle, scikit-image", (741, 500), F_PX, CX0_PX, CY_PX, DOFFS_PX,
    BASELINE_MM, {
        "tank": Target((325, 150, 175, 100)),  # fuel tank with its side panel, YAMAHA lettering, highlights
        "fender": Target((500, 258, 150, 60)),  # front mudguard, a curved thin shell
        "crate": Target((515, 175, 105, 80)),  # red plastic crate on the shelf, partly behind the fork, ~3.7 m
    }, _motorcycle_full)
ALOE = StereoPair(
    "aloe", "Middlebury 2006 Aloe, Debian opencv-doc", ALOE_SIZE, ALOE_F_PX, (ALOE_SIZE[0] - 1) / 2,
    (ALOE_SIZE[1] - 1) / 2, ALOE_DMIN_PX, ALOE_BASELINE_MM, {
        # terracotta pot, ~1.57 m, its left rim behind a leaf; the backdrop's motifs share its hues
        "pot": Target((700, 790, 390, 310), seed=(900, 950), hues=(0, 30, 70)),
        # the long leaf lower left, ~1.8 m long side on a green-patterned backdrop, cut where it joins
        "leaf": Target((70, 600, 680, 140), seed=(400, 680)),
        # an upright leaf (right of centre), its base among the others
        "upright": Target((840, 20, 220, 600), seed=(960, 300)),
    }, _aloe_full, default_scale=0.5)
PAIRS = {p.name: p for p in (MOTORCYCLE, ALOE)}

TARGETS: dict[str, tuple[int, int, int, int]] = {n: t.box for n, t in MOTORCYCLE.targets.items()}
VARIANTS = ("left", "right", "scaled")
SCALED_FACTOR = 0.6  # the "another scale" photo: the left cut resized by this factor
MARGIN_PX = 16  # crop margin around the target's box (full-size px)
BACKDROP = 200  # grey level of the plain backdrop the target is cut out onto


def get_pair(name: str) -> StereoPair:
    if name not in PAIRS:
        raise InputError(f"pair '{name}': choose from {', '.join(PAIRS)}")
    return PAIRS[name]


def stereo_pair(pair: StereoPair, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(left BGR, right BGR, disparity of the left image (float32 px, NaN where unknown)) of
    `pair`, resized by `scale` (disparity scaled with it)."""
    left, right, disp = pair.load()
    if scale != 1.0:
        size = (round(left.shape[1] * scale), round(left.shape[0] * scale))
        left = cv2.resize(left, size, interpolation=cv2.INTER_AREA)
        right = cv2.resize(right, size, interpolation=cv2.INTER_AREA)
        # nearest: averaging disparities across a depth edge would invent surfaces
        disp = cv2.resize(disp, size, interpolation=cv2.INTER_NEAREST) * np.float32(scale)
    return left, right, disp


def pair_rig(pair: StereoPair, scale: float = 1.0) -> Rig:
    """The pair's rig (module docstring) for images resized by `scale`."""
    def cam(cx: float) -> Camera:
        s = scale
        K = np.array([[pair.f_px * s, 0.0, (cx + 0.5) * s - 0.5], [0.0, pair.f_px * s, (pair.cy_px + 0.5) * s - 0.5],
                      [0.0, 0.0, 1.0]])
        return Camera((round(pair.size[0] * s), round(pair.size[1] * s)), K, np.zeros(5))

    return Rig(left=cam(pair.cx0_px), right=cam(pair.cx0_px + pair.doffs_px), R=np.eye(3),
               T=np.array([-pair.baseline_mm, 0.0, 0.0]))


def motorcycle_pair(scale: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The motorcycle pair (`stereo_pair`). Needs scikit-image (the `test` extra)."""
    return stereo_pair(MOTORCYCLE, scale)


def motorcycle_rig(scale: float = 1.0) -> Rig:
    """The motorcycle pair's rig (`pair_rig`)."""
    return pair_rig(MOTORCYCLE, scale)


def depth_from_disparity(disp: np.ndarray, scale: float = 1.0, pair: StereoPair = MOTORCYCLE) -> np.ndarray:
    """Depth (mm, NaN where unknown) from a disparity map of the pair resized by `scale`."""
    return (pair.f_px * scale) * pair.baseline_mm / (disp + np.float32(pair.doffs_px * scale))


def right_disparity(disp: np.ndarray) -> np.ndarray:
    """The left disparity forward-warped to the right image (x_r = x_l - d), the nearest surface
    (largest disparity) kept where several land on one pixel; NaN where none does."""
    H, W = disp.shape
    ys, xs = np.nonzero(np.isfinite(disp))
    d = disp[ys, xs]
    xr = np.rint(xs - d).astype(int)
    ok = (xr >= 0) & (xr < W)
    out = np.full((H, W), -np.inf, np.float32)
    np.maximum.at(out, (ys[ok], xr[ok]), d[ok])
    return np.where(np.isfinite(out), out, np.nan).astype(np.float32)


def _largest_filled(mask: np.ndarray) -> np.ndarray:
    """The largest 8-connected component of a bool mask, holes filled (uint8 0/1)."""
    n, lab, st, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if n <= 1:
        return np.zeros(mask.shape, np.uint8)
    comp = (lab == 1 + int(np.argmax(st[1:, cv2.CC_STAT_AREA]))).astype(np.uint8)
    filled = comp.copy()
    contours, _ = cv2.findContours(comp, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(filled, contours, -1, 1, -1)
    return filled


def red_region(bgr: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray:
    """The target's region in an image (bool, full image): red pixels (hue within 8 OpenCV steps
    of 0, saturation > 90, value > 40) inside `box`, their largest 8-connected component, holes
    filled."""
    x, y, w, h = box
    hsv = cv2.cvtColor(bgr[y:y + h, x:x + w], cv2.COLOR_BGR2HSV)
    hh = hsv[..., 0].astype(int)
    red = ((hh <= 8) | (hh >= 172)) & (hsv[..., 1] > 90) & (hsv[..., 2] > 40)
    if not red.any():
        raise InputError(f"no red region in box {box}")
    out = np.zeros(bgr.shape[:2], bool)
    out[y:y + h, x:x + w] = _largest_filled(red) > 0
    return out


def surface_region(bgr: np.ndarray, disp: np.ndarray, box: tuple[int, int, int, int], seed: tuple[int, int],
                   hues: tuple[int, int, int] | None = None, step_px: float = 1.0) -> np.ndarray:
    """The target's region in an image (bool, full image): the pixels inside `box` reached from
    `seed` over neighbours whose disparity differs by at most `step_px` (unknown disparity stops
    it; single unknown pixels, e.g. a forward-warped map's rounding gaps, take their largest
    neighbour first), kept where the hue is within `hues` (lo, hi, s_min) when given; its largest
    8-connected component, holes filled. A box reaching past the image is cut at its border."""
    H, W = disp.shape
    x0, y0 = max(0, box[0]), max(0, box[1])
    x, y, w, h = x0, y0, min(W, box[0] + box[2]) - x0, min(H, box[1] + box[3]) - y0
    d = disp[y:y + h, x:x + w]
    near = cv2.dilate(np.where(np.isfinite(d), d, -1e4).astype(np.float32), np.ones((3, 3), np.uint8))
    d = np.where(np.isfinite(d), d, near).astype(np.float32)
    d = np.where(d > -1e3, d, -1e4).astype(np.float32)
    sx, sy = seed[0] - x, seed[1] - y
    if not (0 <= sx < w and 0 <= sy < h) or d[sy, sx] < 0:
        raise InputError(f"seed {seed} is not on a known surface inside box {box}")
    m = np.zeros((h + 2, w + 2), np.uint8)
    cv2.floodFill(d, m, (int(sx), int(sy)), 0, step_px, step_px, flags=8 | cv2.FLOODFILL_MASK_ONLY | (255 << 8))
    reg = m[1:-1, 1:-1] > 0
    if hues is not None:
        hsv = cv2.cvtColor(bgr[y:y + h, x:x + w], cv2.COLOR_BGR2HSV)
        lo, hi, s_min = hues
        reg &= (hsv[..., 0] >= lo) & (hsv[..., 0] <= hi) & (hsv[..., 1] >= s_min)
    out = np.zeros(bgr.shape[:2], bool)
    out[y:y + h, x:x + w] = _largest_filled(reg) > 0
    return out


def target_region(target: Target, bgr: np.ndarray, disp: np.ndarray, box: tuple[int, int, int, int],
                  seed: tuple[int, int] | None) -> np.ndarray:
    """The region of `target` in an image with its disparity, box and seed at the image's size."""
    if target.seed is None:
        return red_region(bgr, box)
    return surface_region(bgr, disp, box, seed, target.hues)


@dataclass(frozen=True)
class RealCase:
    """One estimator run on the real pair: the photo (BGR), its photo-model, the stereo pair and its
    rig, and the ground truth (module docstring)."""

    target: str
    variant: str
    photo: np.ndarray
    model: PhotoModel
    left: np.ndarray
    right: np.ndarray
    rig: Rig
    truth: dict


def real_cases(photo_params: PhotoModelParams, scale: float = 1.0, targets: tuple[str, ...] | None = None,
               variants: tuple[str, ...] = VARIANTS, pair: str = "motorcycle") -> list[RealCase]:
    """Every (target, variant) case on `pair` resized by `scale` (module docstring); targets
    default to all of the pair's."""
    spec = get_pair(pair)
    targets = tuple(spec.targets) if targets is None else targets
    left, right, disp = stereo_pair(spec, scale)
    rig = pair_rig(spec, scale)
    Z_left = depth_from_disparity(disp, scale, spec)
    disp_r = right_disparity(disp)
    Z_right = depth_from_disparity(disp_r, scale, spec)
    H, W = left.shape[:2]
    cases = []
    for name in targets:
        if name not in spec.targets:
            raise InputError(f"target '{name}' of pair '{pair}': choose from {', '.join(spec.targets)}")
        target = spec.targets[name]
        box = tuple(round(v * scale) for v in target.box)
        seed = None if target.seed is None else tuple(round(v * scale) for v in target.seed)
        region = target_region(target, left, disp, box, seed)
        d_med = float(np.nanmedian(disp[region]))
        for variant in variants:
            if variant not in VARIANTS:
                raise InputError(f"variant '{variant}': choose from {', '.join(VARIANTS)}")
            x, y, w, h = box
            if variant == "right":
                x = round(x - d_med)
            src, Z, cam = (right, Z_right, rig.right) if variant == "right" else (left, Z_left, rig.left)
            if variant != "right":
                cut = region
            else:
                seed_r = None if seed is None else (round(seed[0] - float(disp[seed[1], seed[0]])), seed[1])
                cut = target_region(target, right, disp_r, (x, y, w, h), seed_r)
            m = round(MARGIN_PX * scale)
            x0, y0 = max(0, x - m), max(0, y - m)
            x1, y1 = min(W, x + w + m), min(H, y + h + m)
            photo = np.where(cut[y0:y1, x0:x1, None], src[y0:y1, x0:x1], np.uint8(BACKDROP)).astype(np.uint8)
            k = 1.0
            if variant == "scaled":
                k = SCALED_FACTOR
                photo = cv2.resize(photo, (round(photo.shape[1] * k), round(photo.shape[0] * k)),
                                   interpolation=cv2.INTER_AREA)
            model = build_photo_model(photo, photo_params)
            # the model's mask and origin in the source image (px)
            ys, xs = np.nonzero(model.mask)
            mx = np.clip(np.rint((xs + 0.5) / k - 0.5 + x0).astype(int), 0, W - 1)
            my = np.clip(np.rint((ys + 0.5) / k - 0.5 + y0).astype(int), 0, H - 1)
            z = Z[my, mx]
            z_med = float(np.nanmedian(z))
            ou = (model.origin_px[0] + 0.5) / k - 0.5 + x0
            ov = (model.origin_px[1] + 0.5) / k - 0.5 + y0
            X = np.array([(ou - cam.K[0, 2]) / cam.K[0, 0], (ov - cam.K[1, 2]) / cam.K[1, 1], 1.0]) * z_med
            if variant == "right":  # X_right = R X_left + T, R = I
                X = rig.R.T @ (X - rig.T)
            alpha = k * cam.K[0, 0] / z_med
            truth = {
                "found": True,
                "position_mm": [float(v) for v in X],
                "rotation": np.eye(3).tolist(),
                "alpha_px_per_mm": float(alpha),
                "size_mm": [float(model.size_px[0] / alpha), float(model.size_px[1] / alpha)],
                "fitness": None, "generations": None, "seconds": None,
                "distance_mm": float(X[2]),
                "target": name, "variant": variant, "scale": scale, "pair": spec.name,
                "box_px": [int(v) for v in box],
                "depth_spread_mm": [float(np.nanpercentile(z, 10)), float(np.nanpercentile(z, 90))],
            }
            cases.append(RealCase(name, variant, photo, model, left, right, rig, truth))
    return cases
