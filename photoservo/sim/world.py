"""The simulated world for `photoservo track --sim` (issue 5, Simulator): a water plane in the arm's
base frame, a target built from a photo and an alpha that drifts, heaves, rolls and pitches with
the waves, optionally a look-alike distractor, and the cameras on the simulated PA-10's flange.

Frames: base frame of the PA-10 (z up, mm). The target's model frame is DESIGN.md's (x along the
photo's columns, y along its rows, z into the photo): a target lying face-up on the water has its
model z pointing down, i.e. R_base_model = Rz(heading) · Rx(roll) · Ry(pitch) · Rx(180°).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from photoservo.errors import InputError
from photoservo.fileio import read_image
from photoservo.geometry import axis_rotation
from photoservo.vision.photo_model import PhotoModel, PhotoModelParams, build_photo_model
from photoservo.vision.measurement import visible_shares
from photoservo.vision.rig import Rig
from photoservo.sim.specimens import specimen
from photoservo.sim.renderer import (
    CameraEffects,
    Foam,
    Scene,
    StereoRenderer,
    calm_water,
    floater_from_model,
    render_view,
)

FACE_UP = np.diag([1.0, -1.0, -1.0])  # Rx(180 deg): model z down into the water
#: `[sim] heave_irregular`: the heave as a sum of sinusoids, (period per heave_period_s, amplitude
#: per heave_mm) each, phases drawn from [sim] seed; RMS that of the one sinusoid (1.01x), periods
#: 1.7-7 s at the default 4 s (what a model of one sinusoid was not fitted on)
IRREGULAR_SEA = ((0.45, 0.30), (0.62, 0.45), (0.95, 0.60), (1.35, 0.50), (1.75, 0.35))
OCCLUSION_RADIUS = 0.8  # `[sim] occlusion_s` foam: patch radius per creature length (covers it to the tips)


@dataclass(frozen=True)
class SimParams:
    """[sim] config: the simulated scene, target motion and cameras."""

    seed: int  # seeds the scene's textures, waves and noise
    specimen: str  # procedural photo of the target: squid, crab or fish
    photo: str  # a photo file instead of the specimen ("" = use the specimen)
    alpha_px_per_mm: float  # true pixel-per-mm ratio of the photo for the simulated creature
    water_z_mm: float  # water surface height in the base frame (mm)
    target_start_mm: tuple[float, float]  # target start (x, y) on the water, base frame (mm)
    heading_deg: float  # target heading at start (deg, about base z)
    drift_mm_s: tuple[float, float]  # drift velocity on the water (mm/s)
    heave_mm: float  # heave amplitude (mm)
    heave_period_s: float
    roll_deg: float  # roll amplitude about the target's x axis (deg)
    roll_period_s: float
    pitch_deg: float  # pitch amplitude about the target's y axis (deg)
    pitch_period_s: float
    distractor: bool  # add a look-alike creature
    distractor_offset_mm: tuple[float, float]  # its offset from the target's start (mm)
    camera_fps: float  # simulated camera frame rate (Hz)
    capture_latency_s: float  # time from exposure to the frame reaching the loop (s)
    lr_skew_s: float  # right camera's exposure delay after the left (s)
    start_offset_mm: float  # arm starts this far (horizontally) from the desired pose (mm)
    start_yaw_deg: float  # ... and yawed this much from it (deg)
    lockstep: bool  # true: simulated clock (deterministic); false: real time
    occlusion_s: tuple[float, ...]  # [t0, t1]: foam over the creature from t0 to t1 (s); [] = never
    heave_irregular: bool = False  # an irregular sea: IRREGULAR_SEA's sinusoids instead of one

    def validate(self, where: str) -> None:
        occ = self.occlusion_s
        if len(occ) not in (0, 2) or (len(occ) == 2 and not 0.0 <= occ[0] < occ[1]):
            raise InputError(f"config key '{where}.occlusion_s' must be [] or [t0, t1] with 0 <= t0 < t1 (s), "
                             f"got {list(occ)}")
        if self.alpha_px_per_mm <= 0:
            raise InputError(f"config key '{where}.alpha_px_per_mm' must be > 0, got {self.alpha_px_per_mm}")
        for name in ("heave_period_s", "roll_period_s", "pitch_period_s", "camera_fps"):
            if getattr(self, name) <= 0:
                raise InputError(f"config key '{where}.{name}' must be > 0, got {getattr(self, name)}")
        if self.specimen not in ("squid", "crab", "fish"):
            raise InputError(f"config key '{where}.specimen' must be squid, crab or fish, got {self.specimen!r}")


@dataclass(frozen=True)
class TargetMotion:
    """Closed-form target motion on the water: constant drift plus sinusoidal heave, roll and
    pitch. All in the base frame (mm, rad, s)."""

    p0: np.ndarray  # (3,) start position on the water surface
    heading: float  # rad
    v: np.ndarray  # (3,) drift velocity (horizontal)
    heave: float  # heave amplitude (mm)...
    heave_period: float  # ...and period (s) of one sinusoid, or:
    roll: float  # rad
    roll_period: float
    pitch: float  # rad
    pitch_period: float
    heave_terms: tuple[tuple[float, float, float], ...] = ()  # (amplitude mm, period s, phase rad) each, if any

    @classmethod
    def from_params(cls, p: SimParams, offset_xy: tuple[float, float] = (0.0, 0.0),
                    heading_offset_deg: float = 0.0) -> "TargetMotion":
        x, y = p.target_start_mm
        return cls(
            p0=np.array([x + offset_xy[0], y + offset_xy[1], p.water_z_mm]),
            heading=math.radians(p.heading_deg + heading_offset_deg),
            v=np.array([p.drift_mm_s[0], p.drift_mm_s[1], 0.0]),
            heave=p.heave_mm, heave_period=p.heave_period_s,
            roll=math.radians(p.roll_deg), roll_period=p.roll_period_s,
            pitch=math.radians(p.pitch_deg), pitch_period=p.pitch_period_s,
            heave_terms=irregular_sea(p.heave_mm, p.heave_period_s, p.seed) if p.heave_irregular else (),
        )

    def pose(self, t: float) -> np.ndarray:
        """T_base_model(t): the target's model frame in the base frame at time t (s)."""
        w_r, w_p = 2 * math.pi / self.roll_period, 2 * math.pi / self.pitch_period
        R = (axis_rotation(2, self.heading) @ axis_rotation(0, self.roll * math.sin(w_r * t))
             @ axis_rotation(1, self.pitch * math.sin(w_p * t + 1.0)) @ FACE_UP)
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = self.p0 + self.v * t + np.array([0.0, 0.0, self.heave_z(t)[0]])
        return T

    def heave_z(self, t: float) -> tuple[float, float]:
        """The heave at time t (s): height above the water's level (mm) and its rate (mm/s)."""
        if not self.heave_terms:
            w_h = 2 * math.pi / self.heave_period
            return self.heave * math.sin(w_h * t), self.heave * w_h * math.cos(w_h * t)
        z = vz = 0.0
        for a, period, phase in self.heave_terms:
            w = 2 * math.pi / period
            z += a * math.sin(w * t + phase)
            vz += a * w * math.cos(w * t + phase)
        return z, vz

    def velocity(self, t: float) -> np.ndarray:
        """Linear velocity of the model origin at time t (mm/s, base frame)."""
        return self.v + np.array([0.0, 0.0, self.heave_z(t)[1]])


def irregular_sea(heave_mm: float, period_s: float, seed: int) -> tuple[tuple[float, float, float], ...]:
    """`[sim] heave_irregular`: IRREGULAR_SEA scaled to heave_mm and period_s, with phases
    drawn from `seed`: ((amplitude mm, period s, phase rad), ...)."""
    phases = np.random.default_rng(seed + 1000).uniform(0.0, 2 * math.pi, len(IRREGULAR_SEA))
    return tuple((a * heave_mm, k * period_s, float(ph)) for (k, a), ph in zip(IRREGULAR_SEA, phases))


def occluded(occlusion_s: tuple[float, ...], t: float) -> bool:
    """Foam over the creature at time t (s): t in `[sim] occlusion_s` = [t0, t1)."""
    return len(occlusion_s) == 2 and occlusion_s[0] <= t < occlusion_s[1]


def in_view(motion: TargetMotion, model: PhotoModel, rig: Rig, alpha: float, T_base_left: np.ndarray,
            t: float) -> float:
    """Truth (issue 10 scores): the share of the creature's inner points S_in inside BOTH images
    at time t (s) with the left camera at T_base_left (4x4, base frame, mm): the smaller of the
    two cameras' shares (vision/measurement.py `visible_shares`) at the true pose and size
    (alpha px/mm); 1.0 = fully in both views. Foam does not change it (`occluded`)."""
    T = np.linalg.inv(T_base_left) @ motion.pose(t)
    if T[2, 3] <= 1.0:
        return 0.0
    return min(visible_shares(T[:3, :3], T[:3, 3], alpha, model, rig))


# ----------------------------------------------------------------------------- the scene


def sim_hand_eye(rig: Rig, standoff_mm: float = 100.0) -> tuple[np.ndarray, np.ndarray]:
    """The simulator's hand-eye transform (X_flange = R · X_left + t): cameras looking along the
    flange's z axis, the rig's centre on the flange axis `standoff_mm` beyond the tool plate."""
    centre_in_left = -rig.R.T @ rig.T / 2.0  # midpoint of the optical centres, left frame
    return np.eye(3), np.array([0.0, 0.0, standoff_mm]) - centre_in_left


SIM_WATER_STRIDE = 4  # render_view's fast path: water shaded per 4x4 block, target at full resolution


class SimScene:
    """What the simulated cameras see: water at `water_z_mm` in the base frame, the target (and
    optionally a look-alike) moving per `TargetMotion`. Renders with sim/renderer.py from the
    camera poses the session hands it (T_base_left at each camera's own exposure time)."""

    def __init__(self, params: SimParams, photo_params: PhotoModelParams, rig: Rig) -> None:
        self.p = params
        self.rig = rig
        self.photo = (read_image(params.photo, "sim.photo") if params.photo
                      else specimen(params.specimen, params.seed))
        self.model = build_photo_model(self.photo, photo_params)
        self.motion = TargetMotion.from_params(params)
        self.distractor_motion = (TargetMotion.from_params(params, params.distractor_offset_mm, 35.0)
                                  if params.distractor else None)
        self.distractor_photo = specimen(params.specimen, params.seed + 1, other=True) if params.distractor else None
        self.distractor_model = (build_photo_model(self.distractor_photo, photo_params)
                                 if params.distractor else None)
        self.water = calm_water(params.seed)
        self.renderer = StereoRenderer(rig)
        self.T_world_base = np.eye(4)
        self.T_world_base[2, 3] = -params.water_z_mm  # synthetic.py's water is the plane z = 0
        self.rng = np.random.default_rng([params.seed, 11])

    def size_mm(self) -> tuple[float, float]:
        return self.model.size_mm(self.p.alpha_px_per_mm)

    def occluded(self, t: float) -> bool:
        """Foam covers the creature at time t (s): `[sim] occlusion_s`."""
        return occluded(self.p.occlusion_s, t)

    def scene(self, t: float) -> Scene:
        T_world_model = self.T_world_base @ self.motion.pose(t)
        target = floater_from_model(self.photo, self.model, self.p.alpha_px_per_mm, T_world_model)
        distractors: tuple = ()
        if self.distractor_motion is not None:
            distractors = (floater_from_model(self.distractor_photo, self.distractor_model,
                                              self.p.alpha_px_per_mm,
                                              self.T_world_base @ self.distractor_motion.pose(t)),)
        foam = None
        if self.occluded(t):  # one foam patch over the whole creature, drifting with it
            radius = OCCLUSION_RADIUS * max(self.size_mm())
            foam = Foam(np.array([[T_world_model[0, 3], T_world_model[1, 3], radius]]), seed=self.p.seed)
        return Scene(water=self.water, target=target, distractors=distractors, foam=foam)

    def in_view(self, T_base_left: np.ndarray, t: float) -> float:
        """Truth: the creature's share in both views at time t (s), `in_view`."""
        return in_view(self.motion, self.model, self.rig, self.p.alpha_px_per_mm, T_base_left, t)

    def render(self, T_base_left: np.ndarray, t_left: float, T_base_left_at_right: np.ndarray,
               t_right: float) -> tuple[np.ndarray, np.ndarray]:
        """Left image exposed at t_left with the left camera at T_base_left; right image at
        t_right with the left camera then at T_base_left_at_right (left/right skew)."""
        r = self.renderer
        water_left, water_right = r.water_rays(SIM_WATER_STRIDE)
        left = render_view(self.scene(t_left), self.rig.left, self.T_world_base @ T_base_left, t_left,
                           self.rng, CameraEffects(noise_sigma=2.0), r.rays_left,
                           water_stride=SIM_WATER_STRIDE, water_rays=water_left)
        T_base_right = T_base_left_at_right @ r.T_left_right
        right = render_view(self.scene(t_right), self.rig.right, self.T_world_base @ T_base_right, t_right,
                            self.rng, CameraEffects(noise_sigma=2.0), r.rays_right,
                            water_stride=SIM_WATER_STRIDE, water_rays=water_right)
        return left, right

    def kernels(self) -> list:
        """The compiled kernels `render` runs (for the session's warm start)."""
        from photoservo.sim import renderer_kernel

        return [renderer_kernel.water_pass, renderer_kernel.world_rays, renderer_kernel.floater_hits,
                renderer_kernel.footprint_values, renderer_kernel.composite_floater]

    def warm(self) -> None:
        """Compile or load the renderer's kernels (issue 10, warm start): one left view from
        hover height over the creature's start, with a throwaway noise generator, so the
        scene's own noise sequence (and every later render) is unchanged."""
        T_base_left = np.eye(4)
        T_base_left[:3, :3] = np.diag([1.0, -1.0, -1.0])  # looking straight down
        T_base_left[:3, 3] = self.motion.pose(0.0)[:3, 3] + np.array([0.0, 0.0, 600.0])
        render_view(self.scene(0.0), self.rig.left, self.T_world_base @ T_base_left, 0.0,
                    np.random.default_rng(0), CameraEffects(noise_sigma=2.0), self.renderer.rays_left,
                    water_stride=SIM_WATER_STRIDE, water_rays=self.renderer.water_rays(SIM_WATER_STRIDE)[0])
