"""The real-time multi-step GA tracker (vision/tracker.py)."""

import dataclasses
import math

import numpy as np
import pytest

from photoservo.robot import pa10
from photoservo.config import load_config
from photoservo.sim.run import build_sim
from photoservo.vision.genes import GeneSpace
from photoservo.vision.fitness import stereo_hue
from photoservo.sim.renderer import Foam, Scene
from photoservo.vision.estimator import acquisition, estimate
from photoservo.vision.pose_search import drive
from photoservo.vision.tracker import Tracker
from photoservo.vision.water_search import on_plane


@pytest.fixture(scope="module")
def sim():
    cfg = load_config(overrides=["sim.drift_mm_s=[0.0, 0.0]", "sim.heave_mm=0.0", "sim.roll_deg=0.0",
                                 "sim.pitch_deg=0.0", "tracker.water_z_mm=-100.0"])
    return cfg, build_sim(cfg)


def test_on_plane_genes_lie_on_the_water_and_face_up(sim):
    cfg, s = sim
    T_base_left = pa10.fk(s.q0) @ s.rig.T_flange_left()
    T_left_base = np.linalg.inv(T_base_left)
    space = GeneSpace("image", s.rig, s.scene.model, cfg.estimator)
    rng = np.random.default_rng(0)
    g = space.full_region().sample(rng, 50)
    g2 = on_plane(g, s.rig.left.K, T_left_base, -100.0)
    assert np.array_equal(g2[:, [0, 1, 3, 6]], g[:, [0, 1, 3, 6]])  # u, v, heading, scale stay free
    R, t, _, _ = space.decode(g2)
    p_base = t @ T_base_left[:3, :3].T + T_base_left[:3, 3]
    assert np.allclose(p_base[:, 2], -100.0, atol=1e-6)
    normal_base = np.einsum("ij,njk->nik", T_base_left[:3, :3], R)[:, :, 2]
    assert np.allclose(normal_base, [0, 0, -1], atol=1e-6)  # model z down into the water


def _frames(cfg, s, t, empty=False, foam=False, shift_mm=(0.0, 0.0)):
    """A stereo frame of the still scene at time t from the arm's start pose, the cameras moved
    horizontally by shift_mm (base frame); empty water, or foam over the whole creature."""
    T = pa10.fk(s.q0) @ s.rig.T_flange_left()
    T[:2, 3] += shift_mm
    scene = s.scene
    sc = scene.scene(t)
    if empty or foam:
        T_m = scene.T_world_base @ scene.motion.pose(t)
        cover = Foam(np.array([[T_m[0, 3], T_m[1, 3], 0.8 * max(scene.size_mm())]]), seed=1) if foam else None
        sc = Scene(water=sc.water, target=None if empty else sc.target, foam=cover)
    left, right = scene.renderer.render(sc, scene.T_world_base @ T, t, water_stride=4)
    return stereo_hue(left, right, cfg.fitness), left, right, T


def _run(tr, cfg, s, t0, n, **kw):
    return [tr.update(*_frames(cfg, s, t0 + k / 30, **kw), t0 + k / 30) for k in range(n)]


def _tracker(cfg, s):
    return Tracker.from_config(s.scene.model, s.rig, cfg, seed=1, time_budget=False)


def _err(tk, s, t):
    return float(np.linalg.norm(tk.T_base_model[:3, 3] - s.scene.motion.pose(t)[:3, 3]))


def test_acquisition_is_spread_over_frames_then_tracks(sim):
    """The whole-volume search runs acquire_generations of its generations per frame (a step
    may finish a refinement past it), no pose meanwhile; then tracking, on the creature, from the
    provisional answer (its one island passed detection) while the search finishes behind the
    track, a quarter of acquire_generations a frame; its final answer is the same one: the track goes on, the search ends."""
    cfg, s = sim
    tr = _tracker(cfg, s)
    tracks = _run(tr, cfg, s, 0.0, 40)
    first = next(k for k, tk in enumerate(tracks) if tk.status == "tracking")
    assert first >= 2, [tk.acquire_generations for tk in tracks]
    assert all(tk.status == "acquiring" and tk.T_base_model is None and tk.acquire_generations >= 1
               and tk.generations == 0 for tk in tracks[:first])
    assert sum(tk.acquire_generations >= cfg.tracker.acquire_generations for tk in tracks[:first]) >= first - 1
    behind = [tk.acquire_generations for tk in tracks[first + 1:]]
    assert 0 < behind.index(0) and all(n == 0 for n in behind[behind.index(0):]), behind
    assert max(behind) <= cfg.tracker.acquire_generations // 4 + 3  # a quarter (a step may run past it)
    assert all(tk.status == "tracking" for tk in tracks[first:]) and tr.acquiring is None
    assert tr.acquisitions == 1 and _err(tracks[-1], s, tracks[-1].t) < 15.0
    assert tracks[-1].alpha == pytest.approx(cfg.sim.alpha_px_per_mm, rel=0.05)


def test_the_provisional_answer_comes_before_the_refinements_and_the_final_threshold_after(sim):
    """The first track comes once the one island converged and passed detection: with fewer of the
    search's generations than the whole search (`estimate`'s) takes; when the search behind the
    track ends, the detection threshold is its final answer's."""
    cfg, s = sim
    tr = _tracker(cfg, s)
    hue, left, right, _ = _frames(cfg, s, 0.0)
    done = drive(acquisition(s.scene.model, left, right, s.rig, cfg.ga, cfg.estimator, cfg.fitness, hue,
                             seed=int(np.random.SeedSequence(1).spawn(2)[1].generate_state(1)[0]), seeded_only=True))
    whole = sum(search.ga.generation for _, search in done.islands)
    tracks = _run(tr, cfg, s, 0.0, 40)
    first = next(k for k, tk in enumerate(tracks) if tk.status == "tracking")
    before = sum(tk.acquire_generations for tk in tracks[:first + 1])
    assert before < 0.8 * whole and len(done.islands) == 1, (before, whole)
    assert tr.threshold == done.results[0][0].threshold


def test_a_final_answer_other_than_the_provisional_one_restarts_the_track_from_it(sim, monkeypatch):
    """When the search behind a provisional track ends on another answer (a turned or mirrored
    twin, another island ranked first), the provisional track is dropped and the track restarts
    from the final answer, measured again on the newest frame."""
    cfg, s = sim
    tr = _tracker(cfg, s)
    monkeypatch.setattr("photoservo.vision.tracker.same_answer", lambda *a: False)
    tracks = _run(tr, cfg, s, 0.0, 40)
    first = next(k for k, tk in enumerate(tracks) if tk.status == "tracking")
    end = first + 1 + [tk.acquire_generations for tk in tracks[first + 1:]].index(0) - 1  # the search's last frame
    assert tracks[end].acquire_generations > 0 and tr.acquiring is None and tr.acquisitions == 1
    assert tracks[end].status == "tracking" and tracks[end].found  # restarted from the final answer, confirmed
    assert all(tk.status == "tracking" for tk in tracks[end:])
    assert _err(tracks[-1], s, tracks[-1].t) < 15.0


def test_acquisition_in_one_frame_tracks_from_it_with_a_sane_velocity(sim):
    """acquire_generations large enough for the whole search: tracking on the first frame, and
    the tracking search's second measurement of that instant leaves the velocity alone."""
    cfg, s = sim
    one = dataclasses.replace(cfg, tracker=dataclasses.replace(cfg.tracker, acquire_generations=100000))
    tr = _tracker(one, s)
    tracks = _run(tr, one, s, 0.0, 4)
    assert [tk.status for tk in tracks] == ["tracking"] * 4
    assert all(np.linalg.norm(tk.velocity_mm_s) < 50.0 and _err(tk, s, tk.t) < 15.0 for tk in tracks)


def test_spread_acquisition_finds_what_estimate_finds(sim):
    """`estimator.acquisition` stopped and resumed between any steps ends where `estimate` does."""
    cfg, s = sim
    hue, left, right, _ = _frames(cfg, s, 0.0)
    args = (s.scene.model, left, right, s.rig, cfg.ga, cfg.estimator, cfg.fitness)
    steps = acquisition(*args, hue, seed=7)
    sizes = []
    while True:
        try:
            sizes.append(next(steps))
        except StopIteration as end:
            done = end.value
            break
    est = estimate(*args, seed=7, frame=hue)
    d, c = done.results[0]
    assert est.found and d.passed and len(sizes) > 20 and set(sizes[:20]) == {1}
    assert np.array_equal(c.position_mm, est.position_mm) and c.alpha == est.alpha_px_per_mm


def test_hidden_creature_is_lost_then_found_again_near_its_track(sim):
    """Foam over the creature: coasting, then lost after lost_frames misses (no pose for the
    arm); once the foam goes, the search around the track has it back on the first frame,
    without a whole-volume search."""
    cfg, s = sim
    tr = _tracker(cfg, s)
    _run(tr, cfg, s, 0.0, 8)
    n = cfg.tracker.lost_frames
    hidden = _run(tr, cfg, s, 0.3, n + 4, foam=True)
    assert [tk.status for tk in hidden[:n - 1]] == ["coasting"] * (n - 1)
    assert all(tk.status == "lost" and tk.T_base_model is None and not tk.found for tk in hidden[n - 1:])
    assert tr.acquiring is None  # the search behind the track ended (no blob pairs under the foam: no other)
    back = _run(tr, cfg, s, 1.0, 3)
    assert [tk.status for tk in back] == ["tracking"] * 3 and tr.acquisitions == 1
    assert _err(back[-1], s, 1.0) < 15.0


def test_creature_leaving_the_view_is_out_of_view_then_found_again(sim):
    """The cameras move away until the creature is out of the right image: out_of_view with no
    pose (never one off the water); back in view, the whole volume finds it again."""
    cfg, s = sim
    tr = _tracker(cfg, s)
    _run(tr, cfg, s, 0.0, 8)
    away = [tr.update(*_frames(cfg, s, 0.3, shift_mm=(0.0, -25.0 * k)), 0.3 + k / 30) for k in range(12)]
    statuses = [tk.status for tk in away]
    assert statuses[0] == "tracking" and statuses[-3:] == ["out_of_view"] * 3, statuses
    assert all(abs(tk.T_base_model[2, 3] - cfg.sim.water_z_mm) < 40.0 for tk in away if tk.T_base_model is not None)
    assert all(tk.T_base_model is None for tk in away if tk.status == "out_of_view")
    back = _run(tr, cfg, s, 1.0, 10)
    first = next(k for k, tk in enumerate(back) if tk.status == "tracking")
    assert first <= 6 and all(tk.status == "tracking" for tk in back[first:]) and tr.acquisitions == 2
    assert _err(back[-1], s, 1.0) < 15.0


def test_max_generations_caps_a_tracking_frame(sim):
    """Replay of a real-time run passes each frame's recorded generation count."""
    cfg, s = sim
    tr = _tracker(cfg, s)
    k = 0
    while tr.search is None:  # the whole-volume search: the cap does not apply
        tr.update(*_frames(cfg, s, k / 30), k / 30, max_generations=3)
        k += 1
    assert tr.update(*_frames(cfg, s, k / 30), k / 30, max_generations=3).generations == 3
    assert tr.update(*_frames(cfg, s, (k + 1) / 30), (k + 1) / 30).generations == cfg.tracker.generations_per_frame


def test_water_gate_plane_and_tilt():
    import cv2

    from photoservo.vision.measurement import water_gate

    T = np.diag([1.0, -1.0, -1.0, 1.0])
    T[2, 3] = -100.0
    assert water_gate(T, -100.0, 40.0, 25.0) == ""
    assert water_gate(T, float("nan"), 40.0, 25.0) == ""
    T2 = T.copy()
    T2[2, 3] = -141.0
    assert water_gate(T2, -100.0, 40.0, 25.0) == "plane"
    for deg, expect in ((20.0, ""), (30.0, "tilt")):
        Tt = T.copy()
        Tt[:3, :3] = cv2.Rodrigues(np.array([math.radians(deg), 0.0, 0.0]))[0] @ T[:3, :3]
        assert water_gate(Tt, -100.0, 40.0, 25.0) == expect, deg


def test_creature_drifting_out_of_a_still_arms_view_is_out_of_view_never_a_pose():
    """`track --sim --no-motion`: the creature drifts out of the right image; the tracker says
    out_of_view, and no pose it gave is a false track (more than 50 mm from the truth)."""
    from photoservo.sim.run import run_lockstep

    cfg = load_config()
    seen = []
    orig = Tracker.update

    def spy(self, *a, **k):
        tk = orig(self, *a, **k)
        seen.append((tk.t, tk.status, None if tk.T_base_model is None else tk.T_base_model[:3, 3].copy()))
        return tk
    Tracker.update = spy
    try:
        run_lockstep(cfg, 4.5, no_motion=True, seed=0)
    finally:
        Tracker.update = orig
    assert seen[-1][1] == "out_of_view"
    sc = build_sim(cfg).scene
    err = [float(np.linalg.norm(p - sc.motion.pose(t)[:3, 3])) for t, _, p in seen if p is not None]
    assert len(err) > 40 and max(err) <= 50.0 and np.median(err) <= 15.0, err


def test_choose_takes_estimates_answer_without_a_track_and_the_tracks_size_nearest_with_one():
    """vision/reacquisition.choose on hand-made candidates (left camera = base frame)."""
    from photoservo.vision.detection import Detection
    from photoservo.vision.pose_search import Candidate
    from photoservo.vision.reacquisition import choose

    def cand(x, alpha, passed, standing):
        d = Detection(score=0.9, null_level=0.2, contrast=standing, outer_on_target=0.0, passed=passed,
                      confidence=0.9, threshold=0.5, standing=standing)
        return d, Candidate(np.eye(3), np.array([x, 0.0, 600.0]), alpha, 0.9, 10, "blob")

    ranked = [cand(0.0, 2.0, False, 0.9), cand(300.0, 2.0, True, 0.6), cand(100.0, 3.0, True, 0.5)]
    assert choose(ranked, np.eye(4), None, None, 0.15) is None  # estimate's best did not pass: not found
    assert choose(ranked[1:], np.eye(4), None, None, 0.15)[1].position_mm[0] == 300.0
    # a track of alpha 2.0 predicted at x = 120: the size rules out the nearer alpha-3 candidate
    assert choose(ranked, np.eye(4), 2.0, np.array([120.0, 0.0, 600.0]), 0.15)[1].position_mm[0] == 300.0
    assert choose(ranked, np.eye(4), 2.9, np.array([120.0, 0.0, 600.0]), 0.15)[1].position_mm[0] == 100.0


def test_a_first_answer_failing_its_confirmation_leaves_the_tracker_acquiring(sim, monkeypatch):
    """Live under load the first whole-volume search ends on a newer frame and its answer may
    fail the confirmation there: the tracker, with no track before, is acquiring again (no
    tracking search around nothing: that crashed the next frame, `t - None`), then finds it."""
    cfg, s = sim
    tr = _tracker(cfg, s)
    monkeypatch.setattr(tr, "_confirm", lambda *a, **k: (None, None, 0))
    tracks = _run(tr, cfg, s, 0.0, 12)
    assert all(tk.status == "acquiring" and tk.T_base_model is None for tk in tracks)
    assert tr.search is None
    monkeypatch.undo()
    tracks = _run(tr, cfg, s, 12 / 30, 12)
    assert tracks[-1].status == "tracking" and _err(tracks[-1], s, 23 / 30) < 15.0


def test_coasting_ends_after_coast_max_s_at_a_low_frame_rate(sim):
    """Under load the loop runs at 3-4 fps: lost_frames misses were 2.5-3 s of coasting on a
    prediction. Coasting also ends coast_max_s after the last measurement."""
    cfg, s = sim
    tr = _tracker(cfg, s)
    tracks = _run(tr, cfg, s, 0.0, 8)
    assert tracks[-1].status == "tracking"
    assert cfg.tracker.lost_frames > 3 and cfg.tracker.coast_max_s == pytest.approx(0.5)
    hidden = [tr.update(*_frames(cfg, s, 0.3 + k / 3, foam=True), 0.3 + k / 3) for k in range(3)]  # 3 fps
    assert [tk.status for tk in hidden] == ["coasting", "coasting", "lost"]  # 0.07, 0.40, 0.73 s after it
    assert hidden[-1].T_base_model is None


def test_an_answer_found_on_its_own_frame_but_late_is_confirmed_on_the_next(sim, monkeypatch):
    """Real time: a whole-volume search that ended on the frame it started on after that frame
    had taken CONFIRM_AFTER_S (here any time at all) is no pose yet: it is measured again on the
    next frame, as an answer that ended on a newer frame is, and tracks from there."""
    cfg, s = sim
    one = dataclasses.replace(cfg, tracker=dataclasses.replace(cfg.tracker, acquire_generations=100000))
    tr = Tracker.from_config(s.scene.model, s.rig, one, seed=1, time_budget=True)
    monkeypatch.setattr("photoservo.vision.tracker.CONFIRM_AFTER_S", 0.0)
    confirms = []
    confirm = tr._confirm
    monkeypatch.setattr(tr, "_confirm", lambda *a, **k: confirms.append(a[-2]) or confirm(*a, **k))
    first = _run(tr, one, s, 0.0, 1)[0]
    assert first.status == "acquiring" and first.T_base_model is None and not confirms and tr.held is not None
    tracks = _run(tr, one, s, 1 / 30, 2)
    assert tracks[0].status == "tracking" and tracks[0].found and confirms == [pytest.approx(1 / 30)]
    assert tracks[1].status == "tracking" and tr.acquisitions == 1 and _err(tracks[1], s, 2 / 30) < 15.0


def test_a_provisional_answer_failing_its_confirmation_counts_one_acquisition(sim, monkeypatch):
    """The provisional answer is counted when taken; when its confirmation fails the search goes
    on, and when it ends it is the same search: one acquisition, not two."""
    cfg, s = sim
    tr = _tracker(cfg, s)
    confirm, calls = tr._confirm, []

    def first_fails(*a, **k):
        calls.append(a[-2])
        return (None, None, 0) if len(calls) == 1 else confirm(*a, **k)
    monkeypatch.setattr(tr, "_confirm", first_fails)
    tracks = _run(tr, cfg, s, 0.0, 40)
    assert len(calls) >= 2 and tracks[-1].status == "tracking", [tk.status for tk in tracks]
    assert tr.acquisitions == 1
