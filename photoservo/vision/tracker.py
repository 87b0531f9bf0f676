"""Real-time multi-step GA tracking (method step 5, issues 5 and 10), eye-in-hand.

Each frame comes with T_base_left, where the left camera (on the arm) was in the base frame (mm)
when it was taken. Population and constant-velocity model live in the BASE frame: the poses are
re-expressed in each frame's camera (`_rebase`), the prediction at the capture time gives a search
window, a few GA generations run within a time budget, and the best pose updates the motion
model (vision/motion_model.py: an alpha-beta filter on position and velocity, a smoothed alpha,
and on known water the height as the fitted heave, an oscillation about a level: vision/heave.py).

A frame's best pose is a measurement when its fitness reaches the detection threshold (the
fitness level that passed the estimator's image-relative detection at the last acquisition,
`detection_threshold` of the chosen candidate: vision/detection.py), at least `min_visible` of
the model is in each image, it lies on known water (`water_gate`) and it is no jump faster than
`max_speed_mm_s`; otherwise the frame is a miss. Status of a frame:

  tracking     measured;
  coasting     a miss, fewer than `lost_frames` in a row and at most `coast_max_s` after the
               last measurement (a loaded machine's 4 fps made 10 frames 2.5 s): the prediction
               stands in (from PAIRS_AFTER_S after the last measurement blob pairs are seeded as
               when lost);
  lost         `lost_frames` misses in a row, or `coast_max_s` without a measurement, while the
               predicted creature is in view (foam,
               glare): no pose. The search stays around the predicted track first — its size is
               known, so alpha stays within `window_alpha_frac`; the position window grows with
               the time since the last measurement up to `search_window_mm`, the heading window
               doubles; target-hue blob pairs near the prediction are seeded with the track's
               orientation and size. Blob pairs only farther away, or LOCAL_SEARCH_S without
               a measurement, start the whole-volume search;
  out_of_view  the predicted creature is less than `min_visible` in either image: it left the
               view; no pose. The whole volume is searched;
  acquiring    no track yet: the whole volume is searched.

The whole-volume search is `estimator.acquisition` — the acquisition of `photoservo estimate`,
blobs matched along epipolar lines, islands, twins and refinements, the same answer for the same
seed — spread over frames: each frame runs `acquire_generations` of its GA generations, more
when the frame came later than 1/REFERENCE_FPS after the one before (`_acquire_share`: a count
set by the frame times, so a replay runs the same search; at 3 fps the spread would only make
the answer seconds staler), on the frame it started on (the creature was seen there). When it ends, the candidates that passed detection are filtered, with a track before,
to those of the track's size (alpha within `size_tolerance`), and the one nearest the prediction
at that frame's time is the measurement; the tracking search restarts around it. When the search
ended on a newer frame (at 2-5 fps its answer is seconds old) the answer is measured again on
that frame (`_confirm`: blob pairs near it seeded, acquire_generations more generations)
and counts only if it passes there; otherwise the track is lost at once. In real time, an answer
found on the frame the search started on but CONFIRM_AFTER_S or more after that frame's update
began (a loaded machine's long frame) is held and confirmed the same way on the next frame.

Provisional answer: when the search has one island (one seed pair: nothing to rank), its fit is
taken as soon as it passed detection (`acquisition(provisional=)`), before the refinements and the
final detection, which are about half the search's CPU (a loaded machine's first track came
seconds later, after the creature had drifted out of the still arm's view). The search then goes
on behind the track, a quarter of acquire_generations a frame (`_final_step`: on a loaded machine a
frame's share would take the generations the tracking search needs); its final answer is chosen
as if the provisional one never was (the track's size and prediction from before it). The same
answer (`same_answer`: position and heading within the tracking window, size within
`size_tolerance`): its threshold and size are the track's, its refined pose is seeded. Another one
(a head-to-tail twin, another island ranked first), or none: the provisional track is dropped and
the track restarts from the final answer, confirmed on the newest frame like any other.

On known water the tracking search scores only poses that pass the water gates (water_search.py):
with a generation or two per frame it otherwise settles on tilted or sunken poses, no measurement.

Pure: arrays in, arrays out; time is whatever clock the caller stamps frames with (s).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from photoservo.geometry import invert_pose, make_pose
from photoservo.vision.detection import Detection
from photoservo.vision.estimator import EstimatorParams, acquisition
from photoservo.vision.fitness import FitnessParams, StereoHue
from photoservo.vision.ga import GAParams
from photoservo.vision.measurement import visible_shares, water_gate
from photoservo.vision.motion_model import MotionModel
from photoservo.vision.photo_model import PhotoModel
from photoservo.vision.pose_search import Candidate, PoseSearch
from photoservo.vision.rig import Rig
from photoservo.vision.reacquisition import Acquiring, choose, near_pairs, same_answer, window_region
from photoservo.vision.water_search import on_plane, on_water_fitness
from photoservo.vision.seeding import BlobPair
from photoservo.vision.track import Status, Track
from photoservo.vision.tracker_params import TrackerParams

LOCAL_SEARCH_S = 1.0  # lost this long after the last measurement: the whole volume is searched too
PAIRS_AFTER_S = 0.5  # the last measurement this old (a loaded machine's long frames): blob pairs seeded
CONFIRM_AFTER_S = 0.25  # real time: a search that ended on its own frame this long after it began is confirmed on the next
REFERENCE_FPS = 30.0  # the frame rate acquire_generations is a per-frame share at (Hz)...
SHARE_MAX = 4  # ...and a later frame's share at most this many times it (longer frames feed on themselves)


class TrackerConfig(Protocol):
    """The sections of the application config (photoservo.config.Config) a Tracker reads; a
    Protocol so that vision/ does not import the application's config (and through it servo/)."""

    tracker: TrackerParams
    ga: GAParams
    estimator: EstimatorParams
    fitness: FitnessParams


@dataclass(frozen=True)
class _Measured:
    """A measurement: pose in the left camera of its frame and in the base frame, capture time (s)."""

    c: Candidate
    T_base_model: np.ndarray
    t: float
    acquired: bool = False  # by the whole-volume search (on the frame it started on)


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
        self.search: PoseSearch | None = None  # the tracking search (tracking, coasting, lost)
        self.acquiring: Acquiring | None = None  # the whole-volume search in progress
        self.status: Status = "acquiring"
        self.misses = 0
        self.frames = 0
        self.motion = MotionModel(params.gain_position, params.gain_velocity, params.gain_alpha, params.water_z_mm)
        self.T_base_left_last: np.ndarray | None = None
        self.acquisitions = 0
        self.threshold = math.inf  # fitness that counts as found: set by each acquisition
        self.t_frame: float | None = None  # capture time of the frame before (s)
        self.share = params.acquire_generations  # this frame's share of the whole-volume search
        self.time_budget = time_budget  # False: always run generations_per_frame (deterministic)
        self.held: _Measured | None = None  # an answer held for confirmation on the next frame (CONFIRM_AFTER_S)

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
        """T_base_model predicted at time t (s) by the motion model (vision/motion_model.py)."""
        return self.motion.predict(t)

    def _in_view(self, T_left_model: np.ndarray) -> bool:
        """At least min_visible of the model in both images at a left-camera pose, track's alpha."""
        return T_left_model[2, 3] > 1.0 and min(visible_shares(
            T_left_model[:3, :3], T_left_model[:3, 3], self.motion.alpha, self.model, self.rig)) >= self.p.min_visible

    # ------------------------------------------------------------------ one frame

    def update(self, frame: StereoHue, left_bgr: np.ndarray, right_bgr: np.ndarray,
               T_base_left: np.ndarray, t: float, max_generations: int | None = None) -> Track:
        """Process one stereo frame captured at time t with the left camera at T_base_left.
        `max_generations`: run at most this many GA generations of the tracking search instead
        of [tracker] generations_per_frame (replay of a real-time run: its recorded counts)."""
        t0 = time.perf_counter()
        self.frames += 1
        self.share, self.t_frame = self._acquire_share(t), t
        T_left_base = invert_pose(T_base_left := np.asarray(T_base_left, dtype=float))
        T_new_old = None if self.T_base_left_last is None else T_left_base @ self.T_base_left_last
        self.T_base_left_last = T_base_left
        gens = self.p.generations_per_frame if max_generations is None else max_generations
        m = acq = best = None
        n = n_acq = 0
        far = False
        if self.search is not None:
            old = self.status == "lost" or t - self.motion.t_last > PAIRS_AFTER_S
            near, far = self._pairs(frame, T_left_base, t) if old else ([], False)
            m, best, n = self._measure_step(frame, T_base_left, T_left_base, T_new_old, t, gens, near)
        behind = (self.acquiring is not None and self.acquiring.taken is not None  # a provisional track's search
                  and self.status in ("tracking", "coasting"))
        held, self.held = self.held, None
        if behind:
            acq, n_acq = self._final_step(frame, left_bgr, right_bgr, T_base_left, t)
            m = m if self.search is not None else None  # not dropped: this frame's measurement stands
        elif m is None and held is not None:  # the answer of the frame before, held for this one
            acq = held
        elif m is None and (self.search is None or far or self.acquiring is not None
                            or (self.status == "lost" and t - self.motion.t_last > LOCAL_SEARCH_S)):
            acq, n_acq = self._acquire_step(frame, left_bgr, right_bgr, T_base_left, t)
        if (acq is not None and acq.t >= t and self.time_budget
                and time.perf_counter() - t0 > CONFIRM_AFTER_S):  # found on this frame, but reported seconds late
            self.held, acq = acq, None
        if acq is not None:  # found on the frame it started on: taken, then confirmed on this one
            track_before = dataclasses.replace(self.motion), self.status
            self._accept(acq)
            self._restart_search(frame, T_left_base @ acq.T_base_model, acq.c.alpha)
            if acq.t < t:
                m, best, n = self._confirm(frame, T_base_left, T_left_base, t, max_generations)
                if m is None:  # the creature moved on from where it was found: the track before stands
                    acq, self.misses = None, self.p.lost_frames - 1
                    self.motion, self.status = track_before
                    if self.acquiring is not None:  # a provisional answer: the search goes on as before
                        self.acquiring.taken = self.acquiring.before = None
        if m is not None:
            if self.acquiring is not None and self.acquiring.taken is None:
                self.acquiring = None
            self._accept(m, restart=acq is not None)
        elif acq is None:
            self._miss(t, T_left_base)
        m = m or acq
        c = None if m is None else _in_camera(m, T_left_base)
        fitness = float(m.c.fitness if m is not None else best.fitness if best is not None else -math.inf)
        return Track(
            t=t, status=self.status, found=m is not None, fitness=fitness,
            T_base_model=self.predict(t) if self.status in ("tracking", "coasting") else None,
            velocity_mm_s=self.motion.velocity(t),
            heave=None if self.motion.heave is None else self.motion.heave.shifted(-t),
            alpha=(a := self.motion.alpha), size_mm=None if a is None else self.model.size_mm(a),
            R_left=None if c is None else c.R, t_left=None if c is None else c.position_mm,
            alpha_measured=None if c is None else c.alpha, generations=n, seconds=time.perf_counter() - t0,
            acquire_generations=n_acq, coast_s=0.0 if self.motion.t_last is None else max(0.0, t - self.motion.t_last),
        )

    def _confirm(self, frame: StereoHue, T_base_left: np.ndarray, T_left_base: np.ndarray, t: float,
                 max_generations: int | None) -> tuple[_Measured | None, Candidate | None, int]:
        """A whole-volume search ended on a frame newer than the one it searched: its answer is
        stale. Measured again on this frame before the arm may use it: the tracking search around
        it, window grown with its age, target-hue blob pairs near it seeded with its orientation
        and size, acquire_generations (at least generations_per_frame) uncut by the time budget."""
        gens = max(self.p.generations_per_frame, self.p.acquire_generations) if max_generations is None \
            else max_generations
        near, _ = self._pairs(frame, T_left_base, t)
        return self._measure_step(frame, T_base_left, T_left_base, None, t, gens, near, budget=False)

    def _measure_step(self, frame: StereoHue, T_base_left: np.ndarray, T_left_base: np.ndarray,
                      T_new_old: np.ndarray | None, t: float, gens: int,
                      near: list[BlobPair], budget: bool = True) -> tuple[_Measured | None, Candidate | None, int]:
        """The tracking search on this frame (`_track_step`; `budget`: cut by the time budget)
        and its best pose tested: (the measurement or None, the best pose, the generations run)."""
        best, n = self._track_step(frame, T_left_base, T_new_old, t, gens, near, budget)
        if best is None or not self._measurement(best, T_base_left, t):
            return None, best, n
        return _Measured(best, T_base_left @ make_pose(best.R, best.position_mm), t), best, n

    def _measurement(self, c: Candidate, T_base_left: np.ndarray, t: float, jump: bool = True) -> bool:
        """Is a frame's best pose (left camera of the frame at T_base_left, time t) a
        measurement: detection threshold, visibility, the water plane, no jump (`jump`)."""
        if not c.fitness >= self.threshold:
            return False
        T_bm = T_base_left @ make_pose(c.R, c.position_mm)
        p = self.p
        if min(visible_shares(c.R, c.position_mm, c.alpha, self.model, self.rig)) < p.min_visible:
            return False
        if water_gate(T_bm, p.water_z_mm, p.plane_margin_mm, p.max_tilt_deg):
            return False
        return not jump or self._plausible(T_bm[:3, 3], t)

    def _plausible(self, p: np.ndarray, t: float) -> bool:
        """A measurement further from the prediction than max_speed allows is a miss."""
        if self.motion.t_last is None:
            return True
        dt = max(t - self.motion.t_last, 1e-3)
        pred = self.motion.p + self.motion.v * dt
        return float(np.linalg.norm(p - pred)) <= (self.p.max_speed_mm_s + self.p.window_growth_mm_s) * dt \
            + self.p.window_position_mm

    # ------------------------------------------------------------------ status

    def _accept(self, m: _Measured, restart: bool = False) -> None:
        """A measurement: tracking. Found again after a loss, or confirming a whole-volume
        search's older answer (`restart`), the position is taken as measured (the prediction is
        old) and the velocity kept; after leaving the view, or by the whole-volume search, the
        motion model starts afresh."""
        if self.status == "out_of_view" or m.acquired:
            self.motion.restart()
        self.motion.correct(m.T_base_model, m.c.alpha, m.t, restart=restart or self.status == "lost")
        self.misses = 0
        self.status = "tracking"

    def _miss(self, t: float, T_left_base: np.ndarray) -> None:  # status of a frame without measurement
        self.misses += 1
        T_pred = self.predict(t)
        if T_pred is None:  # no track (e.g. a whole-volume answer that failed its confirmation)
            self.status = "acquiring"
            self.search = None  # nothing to search around: the whole volume is searched
        elif not self._in_view(T_left_base @ T_pred):
            self.status = "out_of_view"  # the predicted creature left the view: never a pose
            self.search = None  # the whole volume is searched for its return, on a frame it is in
            if self.acquiring is not None and self.acquiring.taken is not None:
                self.acquiring = None  # (a search behind the track runs on a frame from before it left)
        elif (self.search is not None and self.misses < self.p.lost_frames
              and (self.motion.t_last is None or t - self.motion.t_last <= self.p.coast_max_s)):
            self.status = "coasting"
        else:
            self.status = "lost"  # the search stays around the predicted track

    # ------------------------------------------------------------------ whole-volume search

    def _acquire_step(self, frame: StereoHue, left_bgr: np.ndarray, right_bgr: np.ndarray,
                      T_base_left: np.ndarray, t: float) -> tuple[_Measured | None, int]:
        """This frame's share of the whole-volume search: starts one on this frame when none
        runs and runs this frame's share of its GA generations (`_acquire_share`). Its answer:
        the chosen candidate (`_chosen`) measured on the frame it started on, if it passes the
        tests: once its one island passed detection (provisional: the search goes on behind the
        track, `_final_step`), or when it ends. Returns (measurement or None, generations run)."""
        if self.acquiring is None:
            seed = int(self.ss.spawn(1)[0].generate_state(1)[0])
            early: list[tuple[Detection, Candidate]] = []
            steps = acquisition(self.model, left_bgr, right_bgr, self.rig, self.ga_params, self.est_params,
                                self.fit_params, frame, seed, seeded_only=True, provisional=early)
            self.acquiring = Acquiring(steps, frame, T_base_left, t, early)
        a = self.acquiring
        n = 0
        try:
            while n < self.share and not (a.provisional and not a.tried):
                n += next(a.steps)
        except StopIteration as end:
            self.acquiring = None
            self.acquisitions += bool(end.value.islands) and not a.counted  # a search ran (none without blob pairs)
            return self._chosen(end.value.results, a, a.before), n
        if a.provisional and not a.tried:  # its one island passed detection: taken before the refinements
            a.tried = True
            T_pred = self.predict(a.t)
            before = self.motion.alpha, None if T_pred is None else T_pred[:3, 3]
            m = self._chosen(a.provisional, a)
            if m is not None:
                a.taken, a.before = m.c, before
                self.acquisitions += not a.counted  # once a search, whether or not it is confirmed
                a.counted = True
            return m, n
        return None, n

    def _final_step(self, frame: StereoHue, left_bgr: np.ndarray, right_bgr: np.ndarray,
                    T_base_left: np.ndarray, t: float) -> tuple[_Measured | None, int]:
        """The search behind a provisional track, a quarter of acquire_generations: when it ends,
        its answer chosen as if the provisional never was (`Acquiring.before`). The same answer as
        the provisional one (`same_answer`: the track's window; a turned or mirrored twin is not):
        its detection threshold is the tracker's. Another answer, or none: the track is dropped
        (no pose) and the answer, if any, is returned to restart the track from. Returns
        (measurement or None, generations run)."""
        a = self.acquiring
        n = 0
        try:
            while n < max(1, self.p.acquire_generations // 4):
                n += next(a.steps)
        except StopIteration as end:
            self.acquiring = None
            chosen = choose(end.value.results, a.T_base_left, *a.before, self.p.size_tolerance)
            p = self.p
            if chosen is not None and same_answer(a.taken, chosen[1], p.window_position_mm, p.window_heading_deg,
                                                  p.size_tolerance):
                d, c = chosen
                self.threshold, self.motion.alpha = d.threshold, c.alpha  # its size, and its refined pose seeded
                if (T_pred := self.predict(t)) is not None and self.search is not None:
                    T = invert_pose(T_base_left) @ make_pose(a.T_base_left[:3, :3] @ c.R, T_pred[:3, 3])
                    self.search.seed(T[:3, :3], T[:3, 3], np.array([c.alpha]))
                return None, n
            self.motion.restart()  # the provisional track was not the search's answer: no pose from it
            self.search, self.status = None, "acquiring"
            return (None if chosen is None else self._chosen([chosen], a, a.before)), n
        return None, n

    def _chosen(self, results: list[tuple[Detection, Candidate]], a: Acquiring,
                before: tuple[float | None, np.ndarray | None] | None = None) -> _Measured | None:
        """The candidate of a whole-volume search's results (`choose`: with the track's alpha and
        predicted position at the search's frame, or `before`) measured on the frame the search
        ran on, if it passes the tests; its detection threshold becomes the tracker's."""
        if before is None:
            T_pred = self.predict(a.t)
            before = self.motion.alpha, None if T_pred is None else T_pred[:3, 3]
        chosen = choose(results, a.T_base_left, *before, self.p.size_tolerance)
        if chosen is None:
            return None
        d, c = chosen
        self.threshold = d.threshold
        if not self._measurement(c, a.T_base_left, a.t, jump=False):
            return None
        return _Measured(c, a.T_base_left @ make_pose(c.R, c.position_mm), a.t, acquired=True)

    def _acquire_share(self, t: float) -> int:
        """The whole-volume search's GA generations for a frame captured at t (s): acquire_generations
        per 1/REFERENCE_FPS since the frame before, within 1..SHARE_MAX times acquire_generations."""
        a = self.p.acquire_generations
        return a if self.t_frame is None else min(SHARE_MAX * a, max(a, round(a * (t - self.t_frame) * REFERENCE_FPS)))

    def _pairs(self, frame: StereoHue, T_left_base: np.ndarray, t: float) -> tuple[list[BlobPair], bool]:
        """The blob pairs near the predicted track (within the grown window plus the creature's
        length: seeded into the search around it; lost, or confirming), and whether any lie only
        farther away (then the whole volume is searched too). ([], False) without a track."""
        T_pred = self.predict(t)
        if T_pred is None:
            return [], False
        reach = self._grown(t - self.motion.t_last) + max(self.model.size_mm(self.motion.alpha))
        return near_pairs(frame, self.model, self.rig, self.est_params, (T_left_base @ T_pred)[:3, 3], reach)

    # ------------------------------------------------------------------ tracking search

    def _restart_search(self, frame: StereoHue, T_left_model: np.ndarray, alpha: float) -> None:
        """The tracking search (re)starts around a pose (left camera of this frame, mm)."""
        if self.search is None:
            self.search = PoseSearch(self.model, self.rig, frame, self.ga_params, self.est_params,
                                     self.fit_params, self.rng)
        R, t = T_left_model[:3, :3], T_left_model[:3, 3]
        self._window(R, t, alpha)
        self.search.seed(R, t, np.array([alpha]))

    def _grown(self, dt: float) -> float:
        """Window half-width dt (s) after the last measurement (mm): grows up to search_window_mm."""
        p = self.p
        return min(p.window_position_mm + p.window_growth_mm_s * max(dt, 0.0),
                   max(p.search_window_mm, p.window_position_mm))

    def _window(self, R: np.ndarray, t_left: np.ndarray, alpha: float, dt: float = 0.0) -> None:
        """Search window around a pose in the left camera frame. Across the line of sight the
        position half-width grows with the time dt (s) since the last measurement (`_grown`);
        along it (depth: the creature floats, it drifts across the view) it stays
        window_position_mm, which with the scale's window holds alpha near the track's. A lost
        track's heading window is twice as wide (it may turn while hidden)."""
        p = self.p
        self.search.ga.set_region(window_region(
            self.search.space, R, t_left, alpha, self._grown(dt), p.window_position_mm,
            p.window_heading_deg * (2.0 if self.status == "lost" else 1.0), p.window_tilt_deg, p.window_alpha_frac))

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

    def _track_step(self, frame: StereoHue, T_left_base: np.ndarray, T_new_old: np.ndarray | None, t: float,
                    max_generations: int, near: list[BlobPair], budget: bool = True) -> tuple[Candidate | None, int]:
        """A few generations in the window around the prediction (lost: the track's pose moved
        onto each blob pair `near` it is seeded too), stopped at the time budget (real time,
        `budget`); the best pose and the generations run."""
        s = self.search
        if T_new_old is not None:
            self._rebase(T_new_old)
        s.set_frame(frame)
        plane = self.p.plane_search and s.space.kind == "image"
        if plane:
            K, wz = self.rig.left.K, self.p.water_z_mm
            s.ga.set_fitness(lambda g: s._fitness(on_plane(g, K, T_left_base, wz)))
        elif math.isfinite(self.p.water_z_mm):
            s.ga.set_fitness(on_water_fitness(s, invert_pose(T_left_base), self.p.water_z_mm,
                                              self.p.plane_margin_mm, self.p.max_tilt_deg))
        T_pred = self.predict(t)
        if T_pred is not None:
            T_lm = T_left_base @ T_pred
            if T_lm[2, 3] > 1.0:
                self._window(T_lm[:3, :3], T_lm[:3, 3], float(self.motion.alpha), t - self.motion.t_last)
                s.seed(T_lm[:3, :3], T_lm[:3, 3], np.array([self.motion.alpha]))
                for pair in near:
                    s.seed(T_lm[:3, :3], pair.position_mm, np.array([self.motion.alpha]))
        t_end = time.perf_counter() + self.p.time_budget_ms * 1e-3
        n = 0
        while n < max_generations:
            s.step(1)
            n += 1
            if budget and self.time_budget and time.perf_counter() >= t_end:
                break
        if plane:
            g, f = s.ga.best()
            R, tl, alpha, _ = s.space.decode(on_plane(g[None], K, T_left_base, wz))
            return (Candidate(R[0], tl[0], float(alpha[0]), float(f), n, "plane") if np.isfinite(f) else None), n
        c = s.best()
        return (c if np.isfinite(c.fitness) else None), n


def _in_camera(m: _Measured, T_left_base: np.ndarray) -> Candidate:
    """A measurement's pose in this frame's left camera (the whole-volume search's: an earlier frame's)."""
    if not m.acquired:
        return m.c
    T = T_left_base @ m.T_base_model
    return Candidate(T[:3, :3], T[:3, 3], m.c.alpha, m.c.fitness, m.c.generations, m.c.source, m.c.aspect)
