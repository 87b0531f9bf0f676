"""The second scene generator ("harbour"): stereo test scenes drawn independently of the first
renderer (`sim/renderer.py`), so that a tuning step made on one is checked on the other
(issue 9). It shares only the rig (`synthetic_rig`, `perturb_rig`), the per-pixel camera rays
(`pixel_rays`), the other-individual matching of the ground truth (`match_individuals`) and the
photo-model builder; creatures, water, occluders and light are its own:

* Creatures are procedural bodies (`draw_creature`): spindle bodies from a centreline and a
  width profile, fins, tapered arms and jointed legs, eyes and spots, coloured by smooth HSV
  gradients along and across the body (`many_hued`: a wrasse/parrotfish-like fish whose hues run
  from blue and green through yellow and orange to magenta, the water's hue among them). Each
  has a height field (a dome over every body part) used for shading only: the body is curved in
  its light, flat in its geometry (the photo-model is flat too).
* The estimator's photo is a studio shot of the creature (`studio_photo`: soft frontal light,
  a plain backdrop); in the scene the same creature is lit by the sun (Lambert + a sky fill +
  Blinn-Phong highlights on the wet body) under a colour cast.
* Water: a spectral height field (power law with a wind direction, synthesised by FFT, two
  scales), Schlick-Fresnel mix of a turbid body colour (teal, green, blue or olive) with a sky
  gradient and clouds, sun glitter.
* Occluders: foam patches and foam bands with ragged, bubbly edges (`foam_split`: a band across
  the creature's middle that cuts its visible region in two), floating debris (leaves, twigs).
* Light and sensor: brightness 0.75-1.15, a colour cast per scene plus a small white-balance
  difference per camera, vignetting, blur 0.4-1.2 px, sensor noise 2-6 DN.

Frames: world mm, z up, water plane z = 0; cameras OpenCV; the model frame of DESIGN.md (a photo
pixel (u, v) at ((u - ox)/alpha, (v - oy)/alpha, 0) mm, z into the photo, so a creature lying
face-up has its model z pointing down into the water).

API: `random_scene(seed, params, photo_params, kind, other_photo, empty, distractor, foam_split,
many_hued, ...)` -> `SyntheticScene` (the same object and truth shape as
`sim/scenes.random_scene`). Creatures and their studio photos: `sim/creatures.py`; water,
occluders, light and the camera image: `sim/harbour_look.py`.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.geometry import make_pose
from photoservo.sim.creatures import KINDS, PHOTO_SIZE, Creature, draw_creature, float_buoy, recoloured, studio_photo
from photoservo.sim.harbour_look import FoamBand, HarbourScene, HarbourWater, Light, Placed, render_camera
from photoservo.sim.scenes import (
    SynthParams,
    SyntheticScene,
    match_individuals,
    perturb_rig,
    scene_truth,
    synthetic_rig,
)
from photoservo.vision.photo_model import PhotoModel, PhotoModelParams, build_photo_model
from photoservo.vision.rig import Rig, project_points


# ----------------------------------------------------------------------------- scene generator


def _lying(position: np.ndarray, heading: float) -> np.ndarray:
    """T_world_model of a creature lying face-up at `position` (world mm), model x at `heading`."""
    c, s = math.cos(heading), math.sin(heading)
    return make_pose(np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]]), np.asarray(position, float))


def _place_rig(rng: np.random.Generator, rig: Rig, corners_world: np.ndarray, target: np.ndarray,
               distance: float, tilt: float) -> np.ndarray | None:
    """T_world_left with `target` (world) at depth `distance` in the left camera, the optical axis
    `tilt` (rad) from straight down, and every corner inside both images (12 px margin)."""
    for _ in range(300):
        az, roll = rng.uniform(-math.pi, math.pi, 2)
        z = np.array([math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az), -math.cos(tilt)])
        x0 = np.cross(z, [0.0, 0.0, 1.0])
        x0 = x0 / np.linalg.norm(x0) if np.linalg.norm(x0) > 1e-6 else np.array([1.0, 0.0, 0.0])
        y0 = np.cross(z, x0)
        x = math.cos(roll) * x0 + math.sin(roll) * y0
        R = np.column_stack([x, np.cross(z, x), z])
        px = rng.uniform([60, 60], [rig.left.width - 61, rig.left.height - 61])
        ray = cv2.undistortPoints(px.reshape(1, 1, 2), rig.left.K, rig.left.dist).reshape(2)
        C = target - R @ (np.array([ray[0], ray[1], 1.0]) * distance)
        if C[2] < 80:
            continue
        T = make_pose(R, C)
        Xl = (corners_world - C) @ R
        Xr = Xl @ rig.R.T + rig.T
        ok = True
        for cam, X in ((rig.left, Xl), (rig.right, Xr)):
            uv = project_points(X, cam)
            ok &= bool(np.all(np.isfinite(uv)) and np.all(uv >= 12) and np.all(uv[:, 0] <= cam.width - 13)
                       and np.all(uv[:, 1] <= cam.height - 13))
        if ok:
            return T
    return None


_WATERS = (  # body colour BGR: teal, green, blue, olive
    (95.0, 92.0, 40.0), (70.0, 95.0, 45.0), (110.0, 70.0, 30.0), (55.0, 88.0, 80.0))


def _split_check(model: PhotoModel, alpha: float, band: FoamBand, T_world_model: np.ndarray) -> bool:
    """Does the band's core cut the creature's photo mask into two pieces, each >= 15 % of it?"""
    ys, xs = np.nonzero(model.mask)
    Xm = np.column_stack([(xs - model.origin_px[0]) / alpha, (ys - model.origin_px[1]) / alpha, np.zeros(len(xs))])
    Pw = Xm @ T_world_model[:3, :3].T + T_world_model[:3, 3]
    c, s = math.cos(band.direction), math.sin(band.direction)
    across = -(Pw[:, 0] - band.centre[0]) * s + (Pw[:, 1] - band.centre[1]) * c
    keep = np.zeros(model.mask.shape, np.uint8)
    keep[ys, xs] = (np.abs(across) > band.half_width * 1.1).astype(np.uint8)
    n, _, stats, _ = cv2.connectedComponentsWithStats(keep, connectivity=8)
    big = np.sort(stats[1:, cv2.CC_STAT_AREA])[::-1] if n > 1 else np.array([])
    return bool(len(big) >= 2 and big[1] >= 0.15 * len(xs))


def _frame_creature(rng: np.random.Generator, rig: Rig, model: PhotoModel, T_wm: np.ndarray, dist: float,
                    tilt: float, length: float) -> tuple[np.ndarray, float]:
    """(T_world_left, length mm) with the creature (photo-model box `length` mm long, shortened by
    0.8 up to 8 times until it fits) inside both images at depth `dist`, tilt `tilt` (rad)."""
    wA, hA = model.size_px
    for _ in range(8):
        corners = np.array([[sx * wA / 2, sy * hA / 2, 0.0] for sx in (-1, 1) for sy in (-1, 1)]) / (wA / length)
        T_wl = _place_rig(rng, rig, corners @ T_wm[:3, :3].T, np.zeros(3), dist, tilt)
        if T_wl is not None:
            return T_wl, length
        length *= 0.8
    raise InputError(f"harbour scene: cannot fit the creature in both images at {dist:.0f} mm")


def _light(rng: np.random.Generator) -> tuple[Light, float]:
    """The sun (elevation 30-70 deg, any azimuth), gain 0.75-1.15, a colour cast of +-8 % per
    channel, per-camera white balance +-2 %, noise 2-6 DN, blur 0.4-1.2 px; and the elevation (deg)."""
    el, az = math.radians(rng.uniform(30, 70)), rng.uniform(-math.pi, math.pi)
    sun = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    cast = 1 + rng.uniform(-0.08, 0.08, 3)
    light = Light(sun_dir=sun, gain=float(rng.uniform(0.75, 1.15)), cast=cast / cast.mean(),
                  white_balance=(1 + rng.uniform(-0.02, 0.02, 3), 1 + rng.uniform(-0.02, 0.02, 3)),
                  noise=float(rng.uniform(2, 6)), blur=float(rng.uniform(0.4, 1.2)))
    return light, math.degrees(el)


def _water(rng: np.random.Generator) -> HarbourWater:
    return HarbourWater(body_bgr=np.array(_WATERS[int(rng.integers(4))]) * rng.uniform(0.85, 1.15),
                        zenith_bgr=np.array([190.0, 140.0, 90.0]), horizon_bgr=np.array([225.0, 220.0, 210.0]),
                        slope=float(rng.uniform(0.03, 0.09)), wind=float(rng.uniform(-math.pi, math.pi)),
                        glitter=float(rng.uniform(0.3, 1.5)), seed=int(rng.integers(1 << 30)))


def _occluders(rng: np.random.Generator, model: PhotoModel, alpha: float, T_wm: np.ndarray, length: float,
               foam_split: bool) -> tuple[np.ndarray, tuple[FoamBand, ...], np.ndarray, bool]:
    """Foam patches (2-4 around, and in a third of the scenes one over ~12 % of the creature),
    a band across the creature's middle with foam_split (and whether it really cuts it in two),
    and 0-5 pieces of debris: (patches, bands, debris, split)."""
    R_wm = T_wm[:3, :3]
    bands: list[FoamBand] = []
    patches = [[*rng.normal(0, 1.5 * length, 2), rng.uniform(0.08, 0.25) * length] for _ in range(int(rng.integers(2, 5)))]
    split = False
    if foam_split:
        along = float(rng.uniform(-0.12, 0.12)) * length
        centre = R_wm @ np.array([along, 0.0, 0.0])
        ax = R_wm @ np.array([1.0, 0.0, 0.0])
        direction = math.atan2(ax[1], ax[0]) + math.pi / 2 + rng.uniform(-0.35, 0.35)
        bands.append(FoamBand((float(centre[0]), float(centre[1])), direction,
                              float(rng.uniform(0.05, 0.08)) * length, 4.0 * length))
        split = _split_check(model, alpha, bands[0], T_wm)
    elif rng.random() < 1 / 3:
        ys, xs = np.nonzero(model.mask)
        k = int(rng.integers(len(xs)))
        pm = np.array([(xs[k] - model.origin_px[0]) / alpha, (ys[k] - model.origin_px[1]) / alpha, 0.0])
        pw = R_wm @ pm
        area = len(xs) / alpha ** 2
        patches.append([pw[0], pw[1], math.sqrt(0.12 * area / math.pi) * 1.1])
    debris = []
    for _ in range(int(rng.integers(0, 6))):
        q = rng.normal(0, 1.2 * length, 2)
        leaf = rng.random() < 0.6
        debris.append([q[0], q[1], rng.uniform(10, 40) if leaf else rng.uniform(30, 90),
                       rng.uniform(5, 15) if leaf else rng.uniform(2, 4), rng.uniform(0, math.pi), 0 if leaf else 1])
    return (np.array(patches, float).reshape(-1, 3), tuple(bands), np.array(debris, float).reshape(-1, 6), split)


def _look_alike(rng: np.random.Generator, seed: int, kind: str, creature: Creature, model: PhotoModel,
                length: float, rig: Rig, T_wl: np.ndarray) -> tuple[Placed | None, dict]:
    """A look-alike (another species, the creature recoloured by 90-150 deg, or a float in its
    mean hue) lying on the water in the left view, at least 1.25 lengths from the creature."""
    choice = ("species", "recolour", "float")[int(rng.integers(3))]
    if choice == "species":
        dc = draw_creature([k for k in KINDS if k != kind][int(rng.integers(2))], seed + 31)
    elif choice == "recolour":
        dc = recoloured(creature, float(rng.choice([-1, 1]) * rng.uniform(90, 150)))
    else:
        inner = np.radians(model.inner_hue.astype(float) * 2)
        dc = float_buoy(float(np.degrees(np.angle(np.mean(np.exp(1j * inner))))), rng)
    d_alpha = PHOTO_SIZE[0] * 0.8 / (length * (0.5 if choice == "float" else rng.uniform(0.8, 1.2)))
    cam = rig.left
    for _ in range(200):
        px = rng.uniform([50, 50], [cam.width - 51, cam.height - 51])
        ray = cv2.undistortPoints(px.reshape(1, 1, 2), cam.K, cam.dist).reshape(2)
        dw = T_wl[:3, :3] @ np.array([ray[0], ray[1], 1.0])
        if dw[2] >= -1e-6:
            continue
        Pw = T_wl[:3, 3] + (-T_wl[2, 3] / dw[2]) * dw
        if np.hypot(*Pw[:2]) > 1.25 * length:
            T_d = _lying(Pw, float(rng.uniform(-math.pi, math.pi)))
            placed = Placed(dc, T_d, d_alpha, (PHOTO_SIZE[0] / 2 - 0.5, PHOTO_SIZE[1] / 2 - 0.5), 0.072 * PHOTO_SIZE[1])
            return placed, {"kind": choice, "position_mm": [float(v) for v in (np.linalg.inv(T_wl) @ T_d)[:3, 3]]}
    return None, {}


def _photos(rng: np.random.Generator, seed: int, kind: str, other_photo: bool, many_hued: bool,
            photo_params: PhotoModelParams) -> tuple[Creature, np.ndarray, PhotoModel, np.ndarray, PhotoModel]:
    """The scene's creature, its studio photo and model (A), and the estimator's photo and model
    (B: A itself, or another individual's)."""
    creature = draw_creature(kind, seed, many_hued=many_hued)
    backdrops = [(232, 234, 236), (214, 224, 230), (200, 204, 205), (226, 232, 224)]
    render_photo = studio_photo(creature, seed, backdrops[int(rng.integers(4))])
    model_A = build_photo_model(render_photo, photo_params)
    if not other_photo:
        return creature, render_photo, model_A, render_photo, model_A
    photo = studio_photo(draw_creature(kind, seed + 7919, other=True, many_hued=many_hued), seed + 1,
                         backdrops[int(rng.integers(4))])
    return creature, render_photo, model_A, photo, build_photo_model(photo, photo_params)


#: the effects every harbour scene has (its truth's "effects")
EFFECTS = ("light", "waves", "glitter", "noise", "blur", "vignetting", "foam", "debris")


def _truth(T_lm: np.ndarray, empty: bool, other_photo: bool, model_A: PhotoModel, model_B: PhotoModel,
           alpha_A: float) -> dict:
    """The estimate JSON of DESIGN.md for the estimator's photo-model (model_B; the creature was
    drawn from model_A at alpha_A px/mm), the creature's model frame in the true left camera
    frame being T_lm (4x4, mm), with distance_mm, same_photo and creature_size_mm."""
    R = T_lm[:3, :3]
    alpha, origin_mm = (alpha_A, np.zeros(3)) if not other_photo else match_individuals(model_A, model_B, alpha_A)
    wA, hA = model_A.size_px
    return {**scene_truth(empty, R, R @ origin_mm + T_lm[:3, 3], alpha, model_B),
            "distance_mm": float(T_lm[2, 3]), "same_photo": not other_photo,
            "creature_size_mm": [float(wA / alpha_A), float(hA / alpha_A)]}


def random_scene(seed: int, params: SynthParams, photo_params: PhotoModelParams, kind: str = "squid",
                 other_photo: bool = False, empty: bool = False, distractor: bool = False,
                 foam_split: bool = False, many_hued: bool = False, distance_mm: float | None = None,
                 tilt_deg: float | None = None, rig: Rig | None = None) -> SyntheticScene:
    """A seeded harbour scene: a procedural creature (`kind`; a new individual per seed) lying
    face-up on the water, seen by `rig` (default `synthetic_rig()`) rendered with the configured
    calibration error (`params.calib_*`; `SyntheticScene.rig` is the rig the estimator is told).
    Geometry from `params`: depth `distance_mm` (default random in params.distance_mm), tilt of
    the optical axis from the creature's normal `tilt_deg` (default up to params.tilt_max_deg),
    length in params.length_mm (shortened to params.max_image_fraction of the image height).
    Everything else (water, light, occluders) is this generator's own (module docstring).

    other_photo: the estimator's photo shows another individual (truth matched by mask area and
    centroid, `match_individuals`, as in `sim/scenes.random_scene`). empty: no creature.
    distractor: a look-alike (another species, a recoloured copy, or a float in the creature's
    hue) elsewhere in view. foam_split: a foam band across the creature's middle that cuts its
    visible region in two. many_hued (fish): the many-hued creature (see `draw_creature`).
    Without foam_split, a third of the scenes get a foam patch over ~12 % of the creature.

    Truth (`_truth`, and): calibration_error, effects, distractors, seed, generator, kind,
    many_hued, foam_split (the band really cuts the creature in two), foam_cover (share of the
    creature under foam, left image) and light."""
    if kind not in KINDS:
        raise InputError(f"kind '{kind}': choose from {', '.join(KINDS)}")
    if many_hued and kind != "fish":
        raise InputError("many_hued: only for kind 'fish'")
    rng = np.random.default_rng([int(seed), 4243])
    rig = synthetic_rig() if rig is None else rig
    rig_true, calib = perturb_rig(rig, rng, params.calib_rotation_deg, params.calib_focal_pct)
    creature, render_photo, model_A, photo, model_B = _photos(rng, seed, kind, other_photo, many_hued, photo_params)
    dist = float(rng.uniform(*params.distance_mm)) if distance_mm is None else float(distance_mm)
    tilt = math.radians(float(rng.uniform(0, params.tilt_max_deg)) if tilt_deg is None else float(tilt_deg))
    T_wm = _lying(np.zeros(3), float(rng.uniform(-math.pi, math.pi)))
    wA, hA = model_A.size_px
    length = float(rng.uniform(*params.length_mm))
    length = min(length, params.max_image_fraction * rig.left.height * dist / rig.left.K[1, 1] / math.hypot(1, hA / wA))
    T_wl, length = _frame_creature(rng, rig_true, model_A, T_wm, dist, tilt, length)
    alpha_A = wA / length
    # body height 0.12 of the photo's height in photo px: a creature about a fifth as thick as wide
    target = Placed(creature, T_wm, alpha_A, model_A.origin_px, 0.12 * hA)
    light, sun_elevation = _light(rng)
    water = _water(rng)
    patches, bands, debris, split = _occluders(rng, model_A, alpha_A, T_wm, length, foam_split)
    placed, dinfo = _look_alike(rng, seed, kind, creature, model_A, length, rig_true, T_wl) if distractor else (None, {})
    scene = HarbourScene(water=water, target=None if empty else target, distractors=() if placed is None else (placed,),
                         patches=patches, bands=bands, debris=debris, light=light, seed=int(seed))
    noise_rng = np.random.default_rng([int(seed), 77])
    T_wr = T_wl @ np.linalg.inv(make_pose(rig_true.R, rig_true.T))
    left, cov_l = render_camera(scene, rig_true.left, T_wl, light.white_balance[0], noise_rng)
    right, cov_r = render_camera(scene, rig_true.right, T_wr, light.white_balance[1], noise_rng)
    scene = dataclasses.replace(scene, coverage=(cov_l[0], cov_r[0]))
    foam_cover = 0.0 if empty else float(np.clip(1 - cov_l[0].sum() / max(float(cov_l[1].sum()), 1e-6), 0, 1))
    light_truth = {"gain": light.gain, "cast_bgr": [float(v) for v in light.cast], "noise_dn": light.noise,
                   "blur_px": light.blur, "sun_elevation_deg": sun_elevation}
    truth = {**_truth(np.linalg.inv(T_wl) @ T_wm, empty, other_photo, model_A, model_B, alpha_A),
             "calibration_error": calib, "effects": list(EFFECTS), "distractors": [dinfo] if dinfo else [],
             "seed": int(seed), "generator": "harbour", "kind": kind, "many_hued": bool(many_hued),
             "foam_split": bool(split), "foam_cover": round(foam_cover, 4), "light": light_truth}
    return SyntheticScene(left=left, right=right, rig=rig, rig_true=rig_true, truth=truth, photo=photo,
                          render_photo=render_photo, scene=scene, T_world_left=T_wl)
