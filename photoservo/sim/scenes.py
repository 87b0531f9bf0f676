"""The seeded scene generator of the estimator's tests and benchmarks (issue 2, item 7) and
`photoservo synth`: `random_scene` lays a photo's creature face-up on rendered water
(sim/renderer.py), seen by a rig that differs from the written one by a calibration error, with
optional effects, look-alikes and foam, and states the ground truth in the estimate-JSON shape.
Also the simulated rig (`synthetic_rig`), its calibration error (`perturb_rig`) and the truth
helpers shared with the second generator (sim/harbour.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.geometry import make_pose as make_transform
from photoservo.sim.renderer import (
    CameraEffects,
    Floater,
    Foam,
    Scene,
    StereoRenderer,
    floater_from_model,
    lying_on_water,
    stereo_transform,
)
from photoservo.sim.water import Water, calm_water
from photoservo.vision.photo_model import PhotoModel, hue_distance
from photoservo.vision.rig import Camera, Rig

EFFECTS = ("waves", "glints", "noise", "blur", "brightness", "white-balance", "chroma", "bend", "foam")
DEFAULT_EFFECTS = ("waves", "glints", "noise")


@dataclass(frozen=True)
class SynthParams:
    """[synthetic] config: ranges and strengths used by `random_scene` / `photoservo synth`."""

    distance_mm: tuple[float, float]  # range of the target's depth in the left camera (mm)
    tilt_max_deg: float  # max angle between the target's normal and the left optical axis (deg)
    length_mm: tuple[float, float]  # range of the creature's length along model x (mm)
    max_image_fraction: float  # the creature's box diagonal stays below this fraction of the image height
    calib_rotation_deg: float  # stereo rotation error of the rendering rig vs the written one (deg)
    calib_focal_pct: float  # focal length error of each rendering camera vs the written one (%)
    wave_slope: float  # RMS slope of the wind waves (rad) with "waves"
    glint: float  # sun glint strength with "glints" (0..2)
    noise_sigma: float  # sensor noise (8-bit DN) with "noise"
    blur_sigma: float  # Gaussian blur (px) with "blur"
    brightness: float  # max relative gain change (both cameras) with "brightness"
    white_balance: float  # max per-channel gain change (each camera) with "white-balance"
    jpeg_quality: int  # JPEG quality (4:2:0 chroma) with "chroma"
    bend: float  # ends lifted by this fraction of the creature's length with "bend"
    foam_cover: float  # foam patch area as a fraction of the creature's area with "foam"

    def validate(self, where: str) -> None:
        lo, hi = self.distance_mm
        if not 50 <= lo <= hi:
            raise InputError(f"config key '{where}.distance_mm': need 50 <= min <= max, got {list(self.distance_mm)}")
        lo, hi = self.length_mm
        if not 1 <= lo <= hi:
            raise InputError(f"config key '{where}.length_mm': need 1 <= min <= max, got {list(self.length_mm)}")
        if not 0 <= self.tilt_max_deg <= 75:
            raise InputError(f"config key '{where}.tilt_max_deg': must be within 0..75, got {self.tilt_max_deg}")
        if not 0.05 <= self.max_image_fraction <= 1:
            raise InputError(f"config key '{where}.max_image_fraction': must be within 0.05..1")
        if not 1 <= self.jpeg_quality <= 100:
            raise InputError(f"config key '{where}.jpeg_quality': must be within 1..100, got {self.jpeg_quality}")
        for k in ("calib_rotation_deg", "calib_focal_pct", "wave_slope", "glint", "noise_sigma",
                  "blur_sigma", "brightness", "white_balance", "bend", "foam_cover"):
            if not getattr(self, k) >= 0:
                raise InputError(f"config key '{where}.{k}': must be >= 0, got {getattr(self, k)}")
        if self.brightness >= 1 or self.white_balance >= 1:
            raise InputError(f"config key '{where}.brightness/white_balance': must be below 1")


@dataclass(frozen=True)
class SyntheticScene:
    """One generated test scene.

    left, right: the rendered images (BGR uint8). rig: the rig as written to rig.toml (what the
    estimator is told); rig_true: the rig that rendered the images (rig plus calibration error).
    truth: ground truth in the estimate-JSON shape (see `random_scene`). photo: the photo the
    estimator is given; render_photo: the photo of the creature actually floating there."""

    left: np.ndarray
    right: np.ndarray
    rig: Rig
    rig_true: Rig
    truth: dict
    photo: np.ndarray
    render_photo: np.ndarray
    scene: Scene
    T_world_left: np.ndarray


def synthetic_rig() -> Rig:
    """The rig written with synthetic scenes: 640x480, f = 800 px, 100 mm baseline, mild barrel
    distortion, slightly different right camera and a 0.5 degree toe-in, like a real calibration."""
    Kl = np.array([[800.0, 0.0, 319.5], [0.0, 800.0, 239.5], [0.0, 0.0, 1.0]])
    Kr = np.array([[804.0, 0.0, 322.1], [0.0, 803.2, 237.8], [0.0, 0.0, 1.0]])
    left = Camera((640, 480), Kl, np.array([-0.10, 0.05, 0.0, 0.0, 0.0]))
    right = Camera((640, 480), Kr, np.array([-0.095, 0.045, 0.0003, -0.0002, 0.0]))
    R, _ = cv2.Rodrigues(np.array([0.001, -np.radians(0.5), 0.0005]))
    return Rig(left=left, right=right, R=R, T=np.array([-100.0, 0.4, 0.8]))


def perturb_rig(rig: Rig, rng: np.random.Generator, rotation_deg: float, focal_pct: float) -> tuple[Rig, dict]:
    """The rig a scene is really rendered with: the written `rig` with a calibration error of
    exactly `rotation_deg` of extra stereo rotation (random axis) and each camera's focal length
    scaled by 1 ± focal_pct/100 (random sign). Returns (rig_true, description)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    dR, _ = cv2.Rodrigues(axis * np.radians(rotation_deg))
    signs = rng.choice([-1.0, 1.0], size=2)

    def cam(c: Camera, sgn: float) -> Camera:
        K = c.K.copy()
        K[0, 0] *= 1 + sgn * focal_pct / 100
        K[1, 1] *= 1 + sgn * focal_pct / 100
        return Camera(c.size, K, c.dist.copy())

    true = Rig(left=cam(rig.left, signs[0]), right=cam(rig.right, signs[1]), R=dR @ rig.R, T=rig.T.copy(),
               hand_eye=rig.hand_eye)
    return true, {"stereo_rotation_deg": float(rotation_deg), "focal_pct": [float(s * focal_pct) for s in signs]}


def _undistort_pixel(cam: Camera, p: np.ndarray) -> np.ndarray:
    crit = (cv2.TERM_CRITERIA_COUNT, 10, 0.0)  # ~1e-9 px for mild distortion; EPS checks cost 3x
    xy = cv2.undistortPointsIter(np.asarray(p, float).reshape(-1, 1, 2), cam.K, cam.dist, None, None, crit)
    return np.column_stack([xy.reshape(-1, 2), np.ones(len(xy))])


def _inside(cam: Camera, uv: np.ndarray, margin: float) -> bool:
    return bool(np.all(np.isfinite(uv)) and np.all(uv >= margin)
                and np.all(uv[:, 0] <= cam.width - 1 - margin) and np.all(uv[:, 1] <= cam.height - 1 - margin))


def _camera_pose(rng: np.random.Generator, rig: Rig, corners_model: np.ndarray, T_world_model: np.ndarray,
                 distance: float, tilt: float, tries: int = 300) -> np.ndarray | None:
    """A left-camera pose T_world_left with the model origin at depth `distance` (mm) in the left
    camera, the model normal at angle `tilt` (rad) from the left optical axis, random azimuth and
    roll, and every model corner inside both images (10 px margin). None if none fits."""
    from photoservo.vision.rig import project_points

    T_rl = stereo_transform(rig)
    P = T_world_model[:3, 3]
    n_down = T_world_model[:3, 2]  # the model normal (z), pointing into the water
    Xw = corners_model @ T_world_model[:3, :3].T + P
    for _ in range(tries):
        phi, roll = rng.uniform(0, 2 * np.pi, 2)
        # optical axis: the model normal tipped by `tilt` towards azimuth phi
        a = np.cross(n_down, [1.0, 0, 0]) if abs(n_down[0]) < 0.9 else np.cross(n_down, [0, 1.0, 0])
        a /= np.linalg.norm(a)
        b = np.cross(n_down, a)
        zc = math.cos(tilt) * n_down + math.sin(tilt) * (math.cos(phi) * a + math.sin(phi) * b)
        e = np.cross(zc, a)
        e /= np.linalg.norm(e)
        f = np.cross(zc, e)
        xc = math.cos(roll) * e + math.sin(roll) * f
        R_wc = np.column_stack([xc, np.cross(zc, xc), zc])
        cam = rig.left
        p = rng.uniform([40, 40], [cam.width - 41, cam.height - 41])
        X_cam = _undistort_pixel(cam, p)[0] * distance
        C = P - R_wc @ X_cam
        if C[2] < 50:  # the rig must be above the water
            continue
        T_wl = make_transform(R_wc, C)
        T_lw = np.linalg.inv(T_wl)
        Xl = Xw @ T_lw[:3, :3].T + T_lw[:3, 3]
        Xr = Xl @ T_rl[:3, :3].T + T_rl[:3, 3]
        if _inside(rig.left, project_points(Xl, rig.left), 10) and _inside(rig.right, project_points(Xr, rig.right), 10):
            return T_wl
    return None


def scene_truth(empty: bool, R: np.ndarray, position: np.ndarray, alpha: float, model: PhotoModel) -> dict:
    """A scene's ground truth in the estimate-JSON shape of DESIGN.md for the estimator's
    photo-model `model` at pose (R, position mm, model in the true left camera frame) and ratio
    alpha (px/mm), plus tilt_deg (angle of the model normal from the optical axis); the pose keys
    are None for empty water."""
    return {
        "found": not empty,
        "position_mm": None if empty else [float(v) for v in position],
        "rotation": None if empty else [[float(v) for v in row] for row in R],
        "alpha_px_per_mm": None if empty else float(alpha),
        "size_mm": None if empty else [float(model.size_px[0] / alpha), float(model.size_px[1] / alpha)],
        "fitness": None, "generations": None, "seconds": None,
        "tilt_deg": float(np.degrees(np.arccos(np.clip(R[2, 2], -1, 1)))),
    }


def match_individuals(model_A: PhotoModel, model_B: PhotoModel, alpha_A: float) -> tuple[float, np.ndarray]:
    """Ground truth for another individual's photo (`random_scene`'s other-photo case): the
    photo-model B of the estimator's photo laid onto creature A (photo-model A at alpha_A px/mm)
    by equal mask area in mm² (alpha_B = alpha_A · sqrt(area_B / area_A)) and coincident mask
    centroids. Returns (alpha_B px/mm, position of B's origin in A's model frame (3,) mm)."""
    def centroid(m: PhotoModel) -> np.ndarray:
        ys, xs = np.nonzero(m.mask)
        return np.array([xs.mean(), ys.mean()])

    s = math.sqrt(np.count_nonzero(model_A.mask) / np.count_nonzero(model_B.mask))  # A px per B px
    xA = centroid(model_A) + (np.array(model_B.origin_px) - centroid(model_B)) * s
    return alpha_A / s, np.array([*(xA - np.array(model_A.origin_px)) / alpha_A, 0.0])


def _buoy_photo(hue: int, rng: np.random.Generator) -> np.ndarray:
    """A 'buoy' look-alike: a shaded disc in the target's hue with a dark band, on white."""
    img = np.full((160, 160, 3), 240, np.uint8)
    hsv = np.uint8([[[hue, 200, 210]]])
    col = cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0, 0].astype(float)
    yy, xx = np.mgrid[0:160, 0:160]
    r = np.hypot(xx - 80, yy - 80)
    disc = r < 60
    shade = np.clip(1.1 - 0.5 * np.hypot(xx - 60, yy - 60) / 80, 0.5, 1.2)
    img[disc] = np.clip(col[None] * shade[disc][:, None], 0, 255).astype(np.uint8)
    band = disc & (np.abs(xx - 80 - 10 * rng.uniform(-1, 1)) < 9)
    img[band] = 60  # a dark band (a white one would join the backdrop and halve the buoy)
    return img


def random_scene(seed: int, params: SynthParams, photo_params, kind: str = "squid",
                 other_photo: bool = False, effects: tuple[str, ...] = DEFAULT_EFFECTS, empty: bool = False,
                 distractor: bool = False, distance_mm: float | None = None, tilt_deg: float | None = None,
                 photo: np.ndarray | None = None, estimator_photo: np.ndarray | None = None,
                 rig: Rig | None = None, split: bool = False) -> SyntheticScene:
    """A seeded test scene for the estimator: a creature lying face-up on water, seen by a rig.

    The creature is `photo` (default: the specimen `kind`, seed 0) at a random length in
    params.length_mm, random heading, depth `distance_mm` (default: random in
    params.distance_mm) in the left camera and tilt `tilt_deg` (default: random up to
    params.tilt_max_deg) between its normal and the left optical axis, fully inside both images.
    The images are rendered with `rig` (default `synthetic_rig()`) perturbed by the configured
    calibration error; `SyntheticScene.rig` is the unperturbed rig the estimator is told.

    other_photo: the estimator gets a photo of ANOTHER individual (`estimator_photo`, default
    the `kind` specimen with other=True) while the `photo` creature floats in the scene.
    empty: no creature (truth found=false). distractor: add a look-alike (another species, a
    recoloured copy of the creature, or a buoy in the creature's hue) elsewhere in view.
    effects: a subset of EFFECTS, magnitudes from `params`.
    split: a band of foam across the creature (perpendicular to its longer box side, 10-18 % of
    that side wide, centred within the middle 40 %), cutting its hue region in two (drawn from a
    random stream of its own: the rest of the scene is the same as without it).
    Ground truth: `_truth`."""
    if photo is not None and other_photo and estimator_photo is None:
        raise InputError("other_photo with a given photo needs the other individual's estimator_photo")
    bad = [e for e in effects if e not in EFFECTS]
    if bad:
        raise InputError(f"effect '{bad[0]}': unknown, choose from {', '.join(EFFECTS)}")
    rng = np.random.default_rng([int(seed), 2024])
    rig = synthetic_rig() if rig is None else rig
    rig_true, calib = perturb_rig(rig, rng, params.calib_rotation_deg, params.calib_focal_pct)
    renderer = StereoRenderer(rig_true)
    render_photo, estimator_photo, model_A, model_B = _photos(kind, photo, estimator_photo, other_photo, photo_params)
    fx = set(effects)
    water = _water(rng, params, fx)
    dist = float(rng.uniform(*params.distance_mm)) if distance_mm is None else float(distance_mm)
    tilt = float(np.radians(rng.uniform(0, params.tilt_max_deg) if tilt_deg is None else tilt_deg))
    heading = float(rng.uniform(-np.pi, np.pi))
    wA, hA = model_A.size_px
    T_world_model = lying_on_water([0.0, 0.0, 0.0], heading)
    length, alpha_A, T_world_left = _place_cameras(rng, params, rig_true, model_A, T_world_model, dist, tilt)
    bend = params.bend * length if "bend" in fx else 0.0
    target = floater_from_model(render_photo, model_A, alpha_A, T_world_model, bend_mm=bend)
    water = _sun_in_view(rng, water, T_world_left)
    d = (_distractor(rng, kind, render_photo, model_A, photo_params, length, renderer.rays_left, rig_true.left,
                     T_world_left) if distractor else None)
    distractors = () if d is None else (d.floater,)
    dinfo = [] if d is None else [{"kind": d.kind, "position_mm": [
        float(v) for v in (np.linalg.inv(T_world_left) @ d.floater.T_world_model)[:3, 3]]}]
    foam = _foam(rng, params, model_A, alpha_A, T_world_model, length) if "foam" in fx else None
    if split:
        foam = _split_band(seed, wA / alpha_A, hA / alpha_A, T_world_model, foam)
    scene = Scene(water=water, target=None if empty else target, distractors=distractors, foam=foam)
    left, right = renderer.render(scene, T_world_left, 0.0, rng, _camera_effects(rng, params, fx))
    truth = {**_truth(empty, np.linalg.inv(T_world_left) @ T_world_model, model_A, model_B, alpha_A,
                      estimator_photo is render_photo),
             "calibration_error": calib, "effects": sorted(fx), "distractors": dinfo, "split": bool(split),
             "seed": int(seed)}
    return SyntheticScene(left=left, right=right, rig=rig, rig_true=rig_true, truth=truth, photo=estimator_photo,
                          render_photo=render_photo, scene=scene, T_world_left=T_world_left)


def _water(rng: np.random.Generator, params: SynthParams, fx: set[str]) -> Water:
    """The scene's water: calm, with waves and glints when those effects are on."""
    water = calm_water(int(rng.integers(1 << 30)), wave_slope=params.wave_slope if "waves" in fx else 0.0,
                       glint=params.glint if "glints" in fx else 0.0)
    return water if "waves" in fx else Water(**{**water.__dict__, "ripple": 0.0})


def _truth(empty: bool, T_left_model: np.ndarray, model_A: PhotoModel, model_B: PhotoModel, alpha_A: float,
           same: bool) -> dict:
    """The scene's ground truth (`random_scene`'s `truth`: the estimate JSON of DESIGN.md plus
    extra keys) of the creature at T_left_model (photo-model A's frame in the TRUE left camera,
    mm) for the photo-model B the estimator builds from ITS photo:
      rotation, position_mm: X_left = R · X_model + position, for that model's frame;
      alpha_px_per_mm: px of the estimator's photo per mm of the floating creature;
      size_mm: that model's size_px / alpha.
    Same photo: exact. Other photo: the two individuals are matched by their masks — equal area
    in mm² (alpha_B = alpha_A · sqrt(area_B / area_A)) and coincident mask centroids — so
    position_mm is where model B's origin (its box centre) lands on the creature, and size_mm is
    B's box at that scale (on the shipped specimens this matching is within 4 % in scale and
    2 px of the best-overlap (IoU) alignment). creature_size_mm is the floating creature's own
    box size (mm). With "bend", the truth is the flat model tangent to the bent body at its
    origin; the ends rise towards the camera by params.bend x length.
    Extra keys here: distance_mm (depth of the creature's model origin), same_photo,
    creature_size_mm; random_scene adds calibration_error, effects, distractors, split, seed."""
    wA, hA = model_A.size_px
    R = T_left_model[:3, :3]
    alpha, origin_mm = (alpha_A, np.zeros(3)) if same else match_individuals(model_A, model_B, alpha_A)
    position = R @ origin_mm + T_left_model[:3, 3]
    return {
        **scene_truth(empty, R, position, alpha, model_B),
        "distance_mm": float(T_left_model[2, 3]),
        "same_photo": bool(same),
        "creature_size_mm": [float(wA / alpha_A), float(hA / alpha_A)],
    }


def _photos(kind: str, photo: np.ndarray | None, estimator_photo: np.ndarray | None, other_photo: bool,
            photo_params) -> tuple[np.ndarray, np.ndarray, PhotoModel, PhotoModel]:
    """(the floating creature's photo, the estimator's photo, their photo-models): `photo` or the
    `kind` specimen; the estimator's is the same object unless another individual's is asked for."""
    from photoservo.sim.specimens import specimen
    from photoservo.vision.photo_model import build_photo_model

    render_photo = specimen(kind, 0) if photo is None else photo
    if estimator_photo is None:
        estimator_photo = specimen(kind, 0, other=True) if other_photo else render_photo
    model_A = build_photo_model(render_photo, photo_params)
    model_B = model_A if estimator_photo is render_photo else build_photo_model(estimator_photo, photo_params)
    return render_photo, estimator_photo, model_A, model_B


def _place_cameras(rng: np.random.Generator, params: SynthParams, rig: Rig, model: PhotoModel,
                   T_world_model: np.ndarray, dist: float, tilt: float) -> tuple[float, float, np.ndarray]:
    """(length mm, alpha px/mm, T_world_left): a random creature length in params.length_mm,
    its box diagonal below max_image_fraction of the image height, shortened by 20 % at a time
    until a left-camera pose at depth `dist` (mm) and `tilt` (rad) sees it in both images."""
    wA, hA = model.size_px
    cam = rig.left
    length = float(rng.uniform(*params.length_mm))
    limit = params.max_image_fraction * cam.height * dist / cam.K[1, 1] / math.hypot(1, hA / wA)
    length = min(length, limit)
    for _ in range(8):
        alpha = wA / length
        corners = np.array([[-wA / 2, -hA / 2, 0], [wA / 2, -hA / 2, 0], [wA / 2, hA / 2, 0], [-wA / 2, hA / 2, 0]]) / alpha
        T_world_left = _camera_pose(rng, rig, corners, T_world_model, dist, tilt)
        if T_world_left is not None:
            return length, alpha, T_world_left
        length *= 0.8
    raise InputError(f"synthetic scene: cannot fit the creature in both images at {dist:.0f} mm and tilt "
                     f"{np.degrees(tilt):.0f} deg")


def _sun_in_view(rng: np.random.Generator, water: Water, T_world_left: np.ndarray) -> Water:
    """The water with its sun near the mirror direction of the central view ray, so glints land
    in or near view."""
    zc = T_world_left[:3, 2]
    mirror = np.array([-zc[0], -zc[1], -zc[2]]) * np.array([-1, -1, 1])
    sun = mirror + rng.normal(0, np.radians(12), 3)
    sun[2] = abs(sun[2]) + 0.2
    return Water(**{**water.__dict__, "sun_dir": tuple(sun / np.linalg.norm(sun))})


@dataclass(frozen=True)
class _LookAlike:
    kind: str  # species, recolour or buoy
    floater: Floater


def _distractor(rng: np.random.Generator, kind: str, photo: np.ndarray, model: PhotoModel, photo_params,
                length: float, rays: np.ndarray, cam: Camera, T_world_left: np.ndarray) -> _LookAlike | None:
    """A look-alike on the water, away from the creature, inside the left view: another species,
    the same shape recoloured (never to the water's hue, ~100), or a buoy in the creature's hue."""
    from photoservo.sim.specimens import specimen
    from photoservo.vision.photo_model import build_photo_model

    choice = ["species", "recolour", "buoy"][int(rng.integers(3))]
    if choice == "species":
        dphoto = specimen([k for k in ("squid", "crab", "fish") if k != kind][int(rng.integers(2))], 0)
    elif choice == "recolour":
        dom = int(np.argmax(np.bincount(model.inner_hue, minlength=180)))
        shifts = [k for k in range(40, 141, 5) if hue_distance(dom + k, 100) > 30 and hue_distance(k, 0) >= 40]
        hsv = cv2.cvtColor(photo, cv2.COLOR_BGR2HSV)
        hsv[..., 0] = ((hsv[..., 0].astype(int) + int(rng.choice(shifts))) % 180).astype(np.uint8)
        dphoto = cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)
    else:
        dphoto = _buoy_photo(int(np.argmax(np.bincount(model.inner_hue, minlength=180))), rng)
    dmodel = build_photo_model(dphoto, photo_params)
    d_alpha = dmodel.size_px[0] / (length * (0.5 if choice == "buoy" else rng.uniform(0.8, 1.2)))
    R_wl, C = T_world_left[:3, :3], T_world_left[:3, 3]
    for _ in range(200):
        p = rng.uniform([40, 40], [cam.width - 41, cam.height - 41]).astype(int)
        dw = R_wl @ rays[p[1], p[0]]
        if dw[2] >= -1e-6:
            continue
        Pw = C + (-C[2] / dw[2]) * dw
        if np.hypot(*Pw[:2]) > 1.3 * length:
            T_d = lying_on_water(Pw, float(rng.uniform(-np.pi, np.pi)))
            return _LookAlike(choice, floater_from_model(dphoto, dmodel, d_alpha, T_d))
    return None


def _foam(rng: np.random.Generator, params: SynthParams, model: PhotoModel, alpha: float,
          T_world_model: np.ndarray, length: float) -> Foam:
    """Foam over a random point of the creature (params.foam_cover of its area) and a few
    patches scattered around."""
    area_mm2 = float(np.count_nonzero(model.mask)) / alpha**2
    ys, xs = np.nonzero(model.mask)
    i = int(rng.integers(len(xs)))
    pm = np.array([(xs[i] - model.origin_px[0]) / alpha, (ys[i] - model.origin_px[1]) / alpha, 0.0])
    pw = T_world_model[:3, :3] @ pm + T_world_model[:3, 3]
    patches = [[pw[0], pw[1], math.sqrt(params.foam_cover * area_mm2 / math.pi)]]
    for _ in range(3):
        q = rng.normal(0, 1.5 * length, 2)
        patches.append([q[0], q[1], rng.uniform(0.05, 0.2) * length])
    return Foam(np.array(patches), seed=int(rng.integers(1 << 30)))


def _split_band(seed: int, w_mm: float, h_mm: float, T_world_model: np.ndarray, foam: Foam | None) -> Foam:
    """`random_scene(split=True)`: a band of foam across the creature (w_mm x h_mm box),
    perpendicular to its longer side, drawn from a random stream of its own."""
    band_rng = np.random.default_rng([int(seed), 77])
    long_, short = max(w_mm, h_mm), min(w_mm, h_mm)
    at = band_rng.uniform(-0.2, 0.2) * long_
    r = band_rng.uniform(0.05, 0.09) * long_  # patch radius: the band is about 2 r wide
    band = []
    for across in np.arange(-0.75 * short, 0.75 * short + 1e-9, 0.8 * r):
        pm = np.array([at, across, 0.0] if w_mm >= h_mm else [across, at, 0.0])
        pw = T_world_model[:3, :3] @ pm + T_world_model[:3, 3]
        band.append([pw[0], pw[1], r])
    old = np.zeros((0, 3)) if foam is None else foam.patches
    return Foam(np.vstack([old, band]), seed=int(band_rng.integers(1 << 30)) if foam is None else foam.seed)


def _camera_effects(rng: np.random.Generator, params: SynthParams, fx: set[str]) -> tuple[CameraEffects, CameraEffects]:
    """Per-camera effects: one gain for both, white balance, blur, noise and chroma loss each."""
    gain = 1 + (rng.uniform(-params.brightness, params.brightness) if "brightness" in fx else 0.0)
    cam_fx = []
    for _ in range(2):
        wb = tuple(1 + rng.uniform(-params.white_balance, params.white_balance, 3)) if "white-balance" in fx else (1.0, 1.0, 1.0)
        cam_fx.append(CameraEffects(blur_sigma=params.blur_sigma if "blur" in fx else 0.0, gain=gain,
                                    white_balance=tuple(float(v) for v in wb),
                                    noise_sigma=params.noise_sigma if "noise" in fx else 0.0,
                                    jpeg_quality=params.jpeg_quality if "chroma" in fx else 0))
    return cam_fx[0], cam_fx[1]
