"""Real-time multi-step GA tracking (method step 5, issue 5 "Tracking"), eye-in-hand.

The cameras ride on the arm, so each frame comes with T_base_left — where the left camera was
(in the arm's base frame, mm) when the frame was taken. The tracker keeps its population and its
constant-velocity motion model in the BASE frame: before a frame is searched, the population's
poses are re-expressed in that frame's camera (`_rebase`), the model's prediction at the capture
time gives a search window, and a few GA generations run within a time budget. The best pose goes
back to the base frame and updates an alpha-beta filter (position, velocity) and a smoothed
alpha (the creature's size does not change).

Lost and re-acquisition: a frame whose best fitness is under the detection threshold is a miss
(the fitness level that passed the estimator's image-relative detection at the last acquisition,
`detection_threshold` of the chosen candidate: vision/detection.py);
after `lost_frames` misses in a row the track is lost and the next frames run the full
acquisition (`estimator.estimate`, blobs matched along epipolar lines). Among its candidates
above the threshold the tracker takes, when it had a track before, the one whose size agrees
with the track's (alpha within `size_tolerance`) and that lies nearest to the last track
position; otherwise the best-scoring one.

Pure: arrays in, arrays out; time is whatever clock the caller stamps frames with (s).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np

from photoservo.errors import InputError
from photoservo.vision.estimator import EstimatorParams, estimate
from photoservo.vision.pose_search import PoseSearch
from photoservo.vision.fitness import FitnessParams, StereoHue
from photoservo.vision.ga import GAParams
from photoservo.vision.photo_model import PhotoModel
from photoservo.geometry import invert_pose, make_pose
from photoservo.vision.measurement import visible_shares, water_gate
from photoservo.vision.rig import Rig

Status = Literal["acquiring", "tracking", "coasting", "lost", "out_of_view"]


@dataclass(frozen=True)
class TrackerParams:
    """[tracker] config: the per-frame GA and the motion model."""

    generations_per_frame: int  # most GA generations per camera frame
    time_budget_ms: float  # stop a frame's generations once this much time is spent (ms)
    window_position_mm: float  # search window: +- this around the predicted position (mm)...
    window_growth_mm_s: float  # ...plus this much per second since the last measurement (mm/s)
    window_heading_deg: float  # ... +- this around the predicted heading (deg)
    window_tilt_deg: float  # ... +- this around the predicted tilt (deg)
    window_alpha_frac: float  # ... alpha within a factor 1 +- this of the track's
    lost_frames: int  # misses in a row before the track is declared lost
    gain_position: float  # alpha-beta filter: position gain (0..1)
    gain_velocity: float  # alpha-beta filter: velocity gain (0..1)
    gain_alpha: float  # smoothing of the size ratio alpha (0..1)
    size_tolerance: float  # re-acquisition: candidate alpha within this fraction of the track's
    max_speed_mm_s: float  # a measured jump faster than this is a miss, not a move (mm/s)
    water_z_mm: float  # water surface height in the base frame (mm); nan = unknown
    plane_search: bool  # search only on the water plane (position on it, heading, alpha)
    plane_margin_mm: float  # known water: a measured origin farther than this from the plane is a miss (mm)
    max_tilt_deg: float  # known water: a measured normal farther than this from the vertical is a miss (deg)
    min_visible: float  # share of S_in inside each image needed to measure; a prediction below: out_of_view

    def validate(self, where: str) -> None:
        w = f"{where}." if where else ""
        if self.generations_per_frame < 1:
            raise InputError(f"config key '{w}generations_per_frame': must be >= 1, got {self.generations_per_frame}")
        if self.lost_frames < 1:
            raise InputError(f"config key '{w}lost_frames': must be >= 1, got {self.lost_frames}")
        for k in ("gain_position", "gain_velocity", "gain_alpha"):
            if not 0.0 < getattr(self, k) <= 1.0:
                raise InputError(f"config key '{w}{k}': must be in (0, 1], got {getattr(self, k)}")
        if self.plane_search and not math.isfinite(self.water_z_mm):
            raise InputError(f"config key '{w}plane_search': needs '{w}water_z_mm' (photoservo calibrate water)")
        for k in ("time_budget_ms", "window_position_mm", "window_alpha_frac", "max_speed_mm_s"):
            if getattr(self, k) <= 0:
                raise InputError(f"config key '{w}{k}': must be > 0, got {getattr(self, k)}")


@dataclass(frozen=True)
class Track:
    """The tracker's answer for one frame. Poses in the BASE frame (mm); `R_left`, `t_left` the
    measured pose in that frame's left camera (for drawing the model on the images)."""

    t: float  # capture time of the frame (s)
    status: Status
    found: bool  # this frame's best fitness passed the detection threshold
    fitness: float
    T_base_model: np.ndarray | None  # filtered target pose
    velocity_mm_s: np.ndarray  # filtered target velocity (base frame)
    alpha: float | None  # filtered px/mm
    size_mm: tuple[float, float] | None
    R_left: np.ndarray | None
    t_left: np.ndarray | None
    alpha_measured: float | None
    generations: int
    seconds: float


class TrackerConfig(Protocol):
    """The sections of the application config (photoservo.config.Config) a Tracker reads; a
    Protocol so that vision/ does not import the application's config (and through it servo/)."""

    tracker: TrackerParams
    ga: GAParams
    estimator: EstimatorParams
    fitness: FitnessParams


class Tracker:
    """One persistent GA following one target through a stream of stereo frames. Build it with
    `Tracker.from_config`."""

    def __init__(self, model: PhotoModel, rig: Rig, params: TrackerParams, ga_params: GAParams,
                 est_params: EstimatorParams, fit_params: FitnessParams, seed: int = 0, *,
                 time_budget: bool = True) -> None:
        self.model, self.rig, self.p = model, rig, params
        self.ga_params, self.est_params, self.fit_params = ga_params, est_params, fit_params
        self.ss = np.random.SeedSequence(seed)
        self.rng = np.random.default_rng(self.ss.spawn(1)[0])
        self.search: PoseSearch | None = None
        self.status: Status = "acquiring"
        self.misses = 0
        self.frames = 0
        self.p_base: np.ndarray | None = None  # filtered position
        self.v_base = np.zeros(3)
        self.R_base: np.ndarray | None = None
        self.alpha: float | None = None
        self.t_last: float | None = None
        self.T_base_left_last: np.ndarray | None = None
        self.acquisitions = 0
        self.threshold = math.inf  # fitness that counts as found: set by each acquisition
        self.time_budget = time_budget  # False: always run generations_per_frame (deterministic)

    @classmethod
    def from_config(cls, model: PhotoModel, rig: Rig, cfg: TrackerConfig, *, seed: int = 0,
                    time_budget: bool = True) -> "Tracker":
        """A tracker for `model` seen through `rig`, with the [tracker], [ga], [estimator] and
        [fitness] sections of `cfg`. `time_budget=False`: every tracking frame runs
        generations_per_frame generations whatever the wall time (lockstep runs and replay:
        deterministic); True: a frame stops at [tracker] time_budget_ms (real time)."""
        return cls(model, rig, cfg.tracker, cfg.ga, cfg.estimator, cfg.fitness, seed, time_budget=time_budget)

    # ------------------------------------------------------------------ prediction

    def predict(self, t: float) -> np.ndarray | None:
        """T_base_model predicted at time t (constant velocity; orientation held)."""
        if self.p_base is None or self.R_base is None or self.t_last is None:
            return None
        T = np.eye(4)
        T[:3, :3] = self.R_base
        T[:3, 3] = self.p_base + self.v_base * (t - self.t_last)
        return T

    # ------------------------------------------------------------------ one frame

    def update(self, frame: StereoHue, left_bgr: np.ndarray, right_bgr: np.ndarray,
               T_base_left: np.ndarray, t: float, max_generations: int | None = None) -> Track:
        """Process one stereo frame captured at time t with the left camera at T_base_left.
        `max_generations`: run at most this many GA generations on a tracking frame instead of
        [tracker] generations_per_frame (replay of a real-time run: its recorded counts)."""
        t0 = time.perf_counter()
        self.frames += 1
        T_base_left = np.asarray(T_base_left, dtype=float)
        T_left_base = invert_pose(T_base_left)
        if self.search is None:
            cand = self._acquire(frame, left_bgr, right_bgr, T_base_left)
            generations = 0 if cand is None else cand[4]
        else:
            cand = self._track_step(frame, T_base_left, T_left_base, t,
                                    self.p.generations_per_frame if max_generations is None else max_generations)
            generations = cand[4] if cand is not None else 0
        self.T_base_left_last = T_base_left
        measured = None
        if cand is not None:
            R_l, t_l, alpha_m, f, _ = cand
            if f >= self.threshold:
                T_bm = T_base_left @ make_pose(R_l, t_l)
                p = self.p
                seen = min(visible_shares(R_l, t_l, alpha_m, self.model, self.rig))
                if (self._plausible(T_bm[:3, 3], t) and seen >= p.min_visible
                        and not water_gate(T_bm, p.water_z_mm, p.plane_margin_mm, p.max_tilt_deg)):
                    measured = (R_l, t_l, alpha_m, f, T_bm)
        fitness = float(cand[3]) if cand is not None else float("-inf")
        if measured is not None:
            self._correct(measured[4], measured[2], t)
            self.misses = 0
            self.status = "tracking"
        else:
            self.misses += 1
            T_pred = self.predict(t)
            T_lp = None if T_pred is None else T_left_base @ T_pred
            if T_lp is not None and (T_lp[2, 3] <= 1.0 or min(visible_shares(
                    T_lp[:3, :3], T_lp[:3, 3], self.alpha, self.model, self.rig)) < self.p.min_visible):
                self.status = "out_of_view"  # the predicted creature left the view: never a pose
                self.search = None
            elif self.search is not None and self.misses >= self.p.lost_frames:
                self.status = "lost"
                self.search = None  # next frame re-acquires from the full volume
            elif self.search is not None:
                self.status = "coasting"
            else:
                self.status = "acquiring" if self.p_base is None else "lost"
        T_pred = self.predict(t) if self.status in ("tracking", "coasting") else None
        return Track(
            t=t, status=self.status, found=measured is not None, fitness=fitness,
            T_base_model=T_pred, velocity_mm_s=self.v_base.copy(),
            alpha=self.alpha, size_mm=None if self.alpha is None else self.model.size_mm(self.alpha),
            R_left=None if measured is None else measured[0], t_left=None if measured is None else measured[1],
            alpha_measured=None if measured is None else measured[2],
            generations=generations, seconds=time.perf_counter() - t0,
        )

    def _plausible(self, p: np.ndarray, t: float) -> bool:
        """A measurement further from the prediction than max_speed allows is a miss."""
        if self.p_base is None or self.t_last is None or self.search is None:
            return True
        dt = max(t - self.t_last, 1e-3)
        pred = self.p_base + self.v_base * dt
        return float(np.linalg.norm(p - pred)) <= (self.p.max_speed_mm_s + self.p.window_growth_mm_s) * dt \
            + self.p.window_position_mm

    def _correct(self, T_bm: np.ndarray, alpha_m: float, t: float) -> None:
        """Alpha-beta update of position/velocity, orientation taken as measured, alpha smoothed."""
        p_m = T_bm[:3, 3]
        if self.p_base is None or self.t_last is None:
            self.p_base, self.v_base = p_m.copy(), np.zeros(3)
            self.alpha = float(alpha_m)
        else:
            dt = max(t - self.t_last, 1e-6)
            pred = self.p_base + self.v_base * dt
            r = p_m - pred
            self.p_base = pred + self.p.gain_position * r
            self.v_base = self.v_base + (self.p.gain_velocity / dt) * r
            self.alpha = float(self.alpha + self.p.gain_alpha * (alpha_m - self.alpha))
        self.R_base = T_bm[:3, :3].copy()
        self.t_last = t

    # ------------------------------------------------------------------ acquisition

    def _acquire(self, frame: StereoHue, left_bgr: np.ndarray, right_bgr: np.ndarray,
                 T_base_left: np.ndarray):
        """Full-volume acquisition; choose the candidate (see module docstring)."""
        self.acquisitions += 1
        seed = int(self.ss.spawn(1)[0].generate_state(1)[0])
        est = estimate(self.model, left_bgr, right_bgr, self.rig, self.ga_params, self.est_params,
                       self.fit_params, seed=seed, frame=frame)
        cands = [c for c in est.candidates if c["found"]]  # passed the estimator's detection tests
        if not cands:
            self.threshold = math.inf  # nothing passed: not found
            best = est.candidates[0] if est.candidates else None
            if best is None:
                return None
            return (np.array(best["rotation"]), np.array(best["position_mm"]), best["alpha_px_per_mm"],
                    best["fitness"], est.generations)
        if self.alpha is not None and self.p_base is not None:
            ok = [c for c in cands if abs(c["alpha_px_per_mm"] / self.alpha - 1.0) <= self.p.size_tolerance]
            pool = ok or cands

            def dist(c: dict) -> float:
                p = T_base_left[:3, :3] @ np.array(c["position_mm"]) + T_base_left[:3, 3]
                return float(np.linalg.norm(p - self.p_base))
            chosen = min(pool, key=dist)
        else:
            chosen = cands[0]
        R, tl, a = np.array(chosen["rotation"]), np.array(chosen["position_mm"]), float(chosen["alpha_px_per_mm"])
        self.threshold = float(chosen["detection_threshold"])
        self.search = PoseSearch(self.model, self.rig, frame, self.ga_params, self.est_params,
                                 self.fit_params, self.rng)
        self._window(R, tl, a)
        self.search.seed(R, tl, np.array([a]))
        if self.p_base is not None:  # a re-acquisition restarts the motion model's velocity
            self.v_base = np.zeros(3)
            self.p_base, self.t_last = None, None
        return (R, tl, a, float(chosen["fitness"]), est.generations)

    # ------------------------------------------------------------------ tracking

    def _window(self, R: np.ndarray, t_left: np.ndarray, alpha: float, dt: float = 0.0) -> None:
        """Search window around a pose in the left camera frame; the position half-width grows
        with the time dt (s) since the last measurement, as the prediction's uncertainty does."""
        p = self.p
        self.search.set_window(R, t_left, alpha, p.window_position_mm + p.window_growth_mm_s * max(dt, 0.0),
                               p.window_heading_deg, p.window_tilt_deg, p.window_alpha_frac)

    def _rebase(self, T_new_old: np.ndarray) -> None:
        """Re-express the population's poses in the new frame's left camera (they live in the
        base frame; the GA's genes are camera-relative)."""
        s = self.search
        R, t, alpha, _ = s.space.decode(s.ga.genes)
        R2 = T_new_old[:3, :3] @ R
        t2 = t @ T_new_old[:3, :3].T + T_new_old[:3, 3]
        ok = t2[:, 2] > 1.0
        g = s.ga.genes.copy()
        if np.any(ok):
            g[ok] = s.space.encode(R2[ok], t2[ok], alpha[ok])
        s.ga.set_genes(g)

    def _track_step(self, frame: StereoHue, T_base_left: np.ndarray, T_left_base: np.ndarray, t: float,
                    max_generations: int):
        s = self.search
        if self.T_base_left_last is not None:
            self._rebase(T_left_base @ self.T_base_left_last)
        s.set_frame(frame)
        plane = self.p.plane_search and s.space.kind == "image"
        if plane:
            K, wz = self.rig.left.K, self.p.water_z_mm
            s.ga.set_fitness(lambda g: s._fitness(on_plane(g, K, T_left_base, wz)))
        T_pred = self.predict(t)
        if T_pred is not None:
            T_lm = T_left_base @ T_pred
            if T_lm[2, 3] > 1.0:
                self._window(T_lm[:3, :3], T_lm[:3, 3], float(self.alpha), t - self.t_last)
                s.seed(T_lm[:3, :3], T_lm[:3, 3], np.array([self.alpha]))
        t_end = time.perf_counter() + self.p.time_budget_ms * 1e-3
        n = 0
        while n < max_generations:
            s.step(1)
            n += 1
            if self.time_budget and time.perf_counter() >= t_end:
                break
        if plane:
            g, f = s.ga.best()
            R, tl, alpha, _ = s.space.decode(on_plane(g[None], K, T_left_base, wz))
            return (R[0], tl[0], float(alpha[0]), float(f), n) if np.isfinite(f) else None
        c = s.best()
        if not np.isfinite(c.fitness):
            return None
        return (c.R, c.position_mm, c.alpha, float(c.fitness), n)


def on_plane(g: np.ndarray, K: np.ndarray, T_left_base: np.ndarray, water_z_mm: float) -> np.ndarray:
    """Plane search (issue 5, Tracking): image-coded genes (u, v, q, psi, tilt_x, tilt_y, ln s)
    (vision/estimator.py) with the inverse depth q and the tilt replaced by those of a target
    lying flat on the water plane z = water_z_mm (base frame): the ray through (u, v) meets the
    plane at depth z, and the model normal (model z, down into the water) is -z_base seen from
    the camera. Only (u, v), the heading psi and the scale remain free."""
    g = np.array(g, dtype=np.float64, copy=True)
    R_lb = T_left_base[:3, :3]
    n = R_lb[:, 2]  # base z (up) in the left camera frame
    p0 = T_left_base[:3, :3] @ np.array([0.0, 0.0, water_z_mm]) + T_left_base[:3, 3]
    xn = (g[:, 0] - K[0, 2]) / K[0, 0]
    yn = (g[:, 1] - K[1, 2]) / K[1, 1]
    denom = n[0] * xn + n[1] * yn + n[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (n @ p0) / denom
    ok = np.isfinite(z) & (z > 1.0)
    g[ok, 2] = 1000.0 / z[ok]
    m = -n  # model normal
    th = math.atan2(math.hypot(m[0], m[1]), m[2])
    ax, ay = -m[1], m[0]
    norm = math.hypot(ax, ay)
    g[:, 4], g[:, 5] = (ax / norm * th, ay / norm * th) if norm > 1e-12 else (0.0, 0.0)
    return g
