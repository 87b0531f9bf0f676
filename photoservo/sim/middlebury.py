"""A real, calibrated stereo pair with ground truth, standing in for the cameras: Middlebury 2014
"Motorcycle" as scikit-image ships it (`skimage.data.stereo_motorcycle()`: left and right
images, 741 x 500 px, rectified, and the ground-truth disparity of the left image).

Calibration (Middlebury's calib.txt for Motorcycle at full resolution: f = 3979.911 px,
cx0 = 1244.772, cx1 = 1369.115, cy = 1019.507 px, doffs = cx1 - cx0 = 124.343 px,
baseline = 193.001 mm; scikit-image downsampled the images by 4 with
`downscale_local_mean` and quotes these numbers divided by 4: f = 994.978 px, cx0 = 311.193,
cy = 254.877, doffs = 31.086 px, baseline 193.001 mm). A 4x area downsampling moves a pixel
centre c to (c + 0.5) / 4 - 0.5 = c / 4 - 0.375: both principal points get that shift here.
Depth from the left image's disparity d (Middlebury: x_right = x_left - d):
Z = baseline · f / (d + doffs) mm. As an OpenCV rig: two pinhole cameras without distortion,
the right one's principal point at cx0 + doffs, R = I, T = (-baseline, 0, 0) mm.

Targets (`TARGETS`): smooth red parts of distinct shapes, each given by a box in the left
image; its region is the red part inside the box (largest connected region of red hue, holes
filled). For each target, three photo variants the estimator may be given (`real_cases`): the
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

from dataclasses import dataclass

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

TARGETS: dict[str, tuple[int, int, int, int]] = {  # name: box (x, y, w, h) in the left image, full size
    "tank": (325, 150, 175, 100),  # fuel tank with its side panel, YAMAHA lettering, highlights
    "fender": (500, 258, 150, 60),  # front mudguard, a curved thin shell
    "crate": (515, 175, 105, 80),  # red plastic crate on the shelf, partly behind the fork, ~3.7 m
}
VARIANTS = ("left", "right", "scaled")
SCALED_FACTOR = 0.6  # the "another scale" photo: the left cut resized by this factor
MARGIN_PX = 16  # crop margin around the target's box (full-size px)
BACKDROP = 200  # grey level of the plain backdrop the target is cut out onto


def motorcycle_pair(scale: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(left BGR, right BGR, disparity of the left image (float32 px, NaN where unknown)),
    resized by `scale` (disparity scaled with it). Needs scikit-image (the `test` extra)."""
    try:
        from skimage import data
    except ImportError:
        raise InputError("the Middlebury pair needs scikit-image: pip install 'photoservo[test]'") from None
    left, right, disp = data.stereo_motorcycle()
    left = np.ascontiguousarray(left[..., ::-1])
    right = np.ascontiguousarray(right[..., ::-1])
    disp = np.where(np.isfinite(disp), disp, np.nan).astype(np.float32)
    if scale != 1.0:
        size = (round(left.shape[1] * scale), round(left.shape[0] * scale))
        left = cv2.resize(left, size, interpolation=cv2.INTER_AREA)
        right = cv2.resize(right, size, interpolation=cv2.INTER_AREA)
        # nearest: averaging disparities across a depth edge would invent surfaces
        disp = cv2.resize(disp, size, interpolation=cv2.INTER_NEAREST) * np.float32(scale)
    return left, right, disp


def motorcycle_rig(scale: float = 1.0) -> Rig:
    """The pair's rig (module docstring) for images resized by `scale`."""
    def cam(cx: float) -> Camera:
        s = scale
        K = np.array([[F_PX * s, 0.0, (cx + 0.5) * s - 0.5], [0.0, F_PX * s, (CY_PX + 0.5) * s - 0.5], [0.0, 0.0, 1.0]])
        return Camera((round(741 * s), round(500 * s)), K, np.zeros(5))

    return Rig(left=cam(CX0_PX), right=cam(CX0_PX + DOFFS_PX), R=np.eye(3), T=np.array([-BASELINE_MM, 0.0, 0.0]))


def depth_from_disparity(disp: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Depth (mm, NaN where unknown) from a disparity map of the pair resized by `scale`."""
    return (F_PX * scale) * BASELINE_MM / (disp + np.float32(DOFFS_PX * scale))


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


def red_region(bgr: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray:
    """The target's region in an image (bool, full image): red pixels (hue within 8 OpenCV steps
    of 0, saturation > 90, value > 40) inside `box`, their largest 8-connected component, holes
    filled."""
    x, y, w, h = box
    hsv = cv2.cvtColor(bgr[y:y + h, x:x + w], cv2.COLOR_BGR2HSV)
    hh = hsv[..., 0].astype(int)
    red = ((hh <= 8) | (hh >= 172)) & (hsv[..., 1] > 90) & (hsv[..., 2] > 40)
    n, lab, st, _ = cv2.connectedComponentsWithStats(red.astype(np.uint8), connectivity=8)
    if n <= 1:
        raise InputError(f"no red region in box {box}")
    comp = (lab == 1 + int(np.argmax(st[1:, cv2.CC_STAT_AREA]))).astype(np.uint8)
    filled = comp.copy()
    contours, _ = cv2.findContours(comp, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(filled, contours, -1, 1, -1)
    out = np.zeros(bgr.shape[:2], bool)
    out[y:y + h, x:x + w] = filled > 0
    return out


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


def real_cases(photo_params: PhotoModelParams, scale: float = 1.0, targets: tuple[str, ...] = tuple(TARGETS),
               variants: tuple[str, ...] = VARIANTS) -> list[RealCase]:
    """Every (target, variant) case on the pair resized by `scale` (module docstring)."""
    left, right, disp = motorcycle_pair(scale)
    rig = motorcycle_rig(scale)
    Z_left = depth_from_disparity(disp, scale)
    disp_r = right_disparity(disp)
    Z_right = depth_from_disparity(disp_r, scale)
    H, W = left.shape[:2]
    cases = []
    for name in targets:
        if name not in TARGETS:
            raise InputError(f"target '{name}': choose from {', '.join(TARGETS)}")
        box = tuple(round(v * scale) for v in TARGETS[name])
        region = red_region(left, box)
        d_med = float(np.nanmedian(disp[region]))
        for variant in variants:
            if variant not in VARIANTS:
                raise InputError(f"variant '{variant}': choose from {', '.join(VARIANTS)}")
            x, y, w, h = box
            if variant == "right":
                x = round(x - d_med)
            src, Z, cam = (right, Z_right, rig.right) if variant == "right" else (left, Z_left, rig.left)
            cut = region if variant != "right" else red_region(right, (x, y, w, h))
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
                "target": name, "variant": variant, "scale": scale,
                "box_px": [int(v) for v in box],
                "depth_spread_mm": [float(np.nanpercentile(z, 10)), float(np.nanpercentile(z, 90))],
            }
            cases.append(RealCase(name, variant, photo, model, left, right, rig, truth))
    return cases
