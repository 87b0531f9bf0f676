"""The real-time multi-step GA tracker (vision/tracker.py)."""

import math

import numpy as np
import pytest

from photoservo.robot import pa10
from photoservo.config import load_config
from photoservo.sim.run import build_sim
from photoservo.vision.pose_search import GeneSpace
from photoservo.vision.fitness import stereo_hue
from photoservo.sim.renderer import Scene
from photoservo.vision.tracker import Tracker, on_plane


@pytest.fixture(scope="module")
def sim():
    cfg = load_config(overrides=["sim.drift_mm_s=[0.0, 0.0]", "sim.heave_mm=0.0", "sim.roll_deg=0.0",
                                 "sim.pitch_deg=0.0"])
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


def _frames(cfg, s, t, empty=False):
    T = pa10.fk(s.q0) @ s.rig.T_flange_left()
    scene = s.scene
    if empty:
        water = scene.scene(t).water
        left, right = (scene.renderer.render(Scene(water=water), scene.T_world_base @ T, t, water_stride=4))
    else:
        left, right = scene.render(T, t, T, t)
    return stereo_hue(left, right, cfg.fitness), left, right, T


def test_tracker_follows_loses_after_n_misses_and_reacquires(sim):
    cfg, s = sim
    tr = Tracker.from_config(s.scene.model, s.rig, cfg, seed=1, time_budget=False)
    truth = s.scene.motion.pose(0.0)[:3, 3]
    statuses = []
    for k in range(4):
        tk = tr.update(*_frames(cfg, s, k / 30), k / 30)
        statuses.append(tk.status)
    assert statuses == ["tracking"] * 4 and tr.acquisitions == 1
    assert np.linalg.norm(tk.T_base_model[:3, 3] - truth) < 15.0
    assert tk.alpha == pytest.approx(cfg.sim.alpha_px_per_mm, rel=0.05)
    for k in range(4, 4 + cfg.tracker.lost_frames):  # the target vanishes (empty water)
        tk = tr.update(*_frames(cfg, s, k / 30, empty=True), k / 30)
        assert not tk.found
    assert tk.status == "lost"
    tk = tr.update(*_frames(cfg, s, 1.0), 1.0)
    assert tk.status == "tracking" and tr.acquisitions == 2
    assert np.linalg.norm(tk.T_base_model[:3, 3] - truth) < 15.0
    assert math.isfinite(tk.fitness)


def test_max_generations_caps_a_tracking_frame(sim):
    """Replay of a real-time run passes each frame's recorded generation count."""
    cfg, s = sim
    tr = Tracker.from_config(s.scene.model, s.rig, cfg, seed=1, time_budget=False)
    tr.update(*_frames(cfg, s, 0.0), 0.0, max_generations=3)  # acquisition: the cap does not apply
    assert tr.search is not None
    assert tr.update(*_frames(cfg, s, 1 / 30), 1 / 30, max_generations=3).generations == 3
    assert tr.update(*_frames(cfg, s, 2 / 30), 2 / 30).generations == cfg.tracker.generations_per_frame


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
