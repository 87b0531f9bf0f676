"""Tracking scores against the simulator's truth (servo/scores.py, issue 10) on hand-made frames,
and on the simulator's clock: foam over the creature for a second, and the creature drifting out
of view of a still arm (sim/run.py run_lockstep)."""

import math

import pytest

from photoservo.config import load_config
from photoservo.servo.scores import TruthFrame, false_tracks, reacquisition_s, track_error_summary
from photoservo.sim.run import run_lockstep

NAN = math.nan


def _frames(rows):
    return [TruthFrame(t, status, in_view, hidden, err) for t, status, in_view, hidden, err in rows]


def test_track_error_counts_only_frames_fully_in_view_with_a_pose():
    fr = _frames([
        (0.0, "acquiring", 1.0, False, NAN),  # no pose
        (0.1, "tracking", 1.0, False, 2.0),
        (0.2, "tracking", 1.0, False, 4.0),
        (0.3, "coasting", 1.0, False, 6.0),
        (0.4, "tracking", 0.7, False, 90.0),  # partly out of view: not counted
        (0.5, "coasting", 1.0, True, 80.0),  # hidden by foam: not counted
    ])
    e = track_error_summary(fr)
    assert e["median"] == 4.0 and 5.0 < e["p95"] <= 6.0
    assert track_error_summary(fr[:1]) == {"median": None, "p95": None}
    assert track_error_summary(fr, partial=True) == {"median": 90.0, "p95": 90.0}


def test_false_tracks_are_poses_out_of_view_or_far_from_the_truth():
    fr = _frames([
        (0.0, "tracking", 1.0, False, 10.0),
        (0.1, "tracking", 0.5, False, 49.0),  # partly in view, near the truth: fine
        (0.2, "coasting", 0.2, False, 51.0),  # too far
        (0.3, "coasting", 0.0, False, 5.0),  # out of view, yet a pose
        (0.4, "out_of_view", 0.0, False, NAN),
        (0.5, "lost", 1.0, True, NAN),
    ])
    assert false_tracks(fr) == 2


def test_reacquisition_per_gap_from_fully_in_view_again_to_tracking():
    fr = _frames([
        (0.0, "acquiring", 0.9, False, NAN),  # not yet fully seen: the start is no gap
        (0.1, "tracking", 1.0, False, 1.0),
        (0.2, "coasting", 1.0, True, NAN),  # gap 1: hidden
        (0.3, "lost", 1.0, True, NAN),
        (0.4, "lost", 1.0, False, NAN),  # visible again at 0.4
        (0.5, "lost", 1.0, False, NAN),
        (0.6, "tracking", 1.0, False, 2.0),  # -> 0.2 s
        (0.7, "tracking", 0.8, False, 3.0),  # gap 2: partly out, still tracked
        (0.8, "tracking", 1.0, False, 3.0),  # -> 0.0 s
        (0.9, "out_of_view", 0.0, False, NAN),  # gap 3: back at 1.0, never tracked again
        (1.0, "lost", 1.0, False, NAN),
    ])
    r = reacquisition_s(fr)
    assert len(r) == 3 and r[0] == pytest.approx(0.2) and r[1] == 0.0 and r[2] is None


def test_foam_over_the_creature_is_waited_out_and_the_track_is_back_within_a_second():
    """`[sim] occlusion_s`: hidden frames are never tracking and give the arm no stale pose;
    once the foam goes, tracking again within 1 s; no false track."""
    cfg = load_config(overrides=["sim.occlusion_s=[1.5, 2.5]", "sim.camera_fps=15", "servo.settle_s=1.0"])
    sc = run_lockstep(cfg, 3.5, seed=0)
    s = sc.summary()
    hidden = [f for f in sc.truth_frames if f.hidden]
    assert hidden and all(f.status in ("coasting", "lost") for f in hidden), s
    assert len(s["reacquisition_s"]) == 1 and s["reacquisition_s"][0] <= 1.0, s
    assert s["false_tracks"] == 0 and s["track_error_mm"]["p95"] <= 15.0, s
    back = [f for f in sc.truth_frames if f.t >= 2.5 + s["reacquisition_s"][0]]
    assert back and all(f.status == "tracking" for f in back), s


def test_creature_drifting_out_of_a_still_arms_view_is_reported_so():
    """`track --sim --no-motion`: the default scene drifts the creature out of the right image;
    status out_of_view at the end, no false track, accurate while fully in view."""
    cfg = load_config()
    sc = run_lockstep(cfg, 4.0, no_motion=True, seed=0)
    s = sc.summary()
    assert s["final_status"] == "out_of_view" and s["false_tracks"] == 0, s
    assert s["track_error_partial_mm"]["p95"] <= 15.0, s  # it is never fully in view of the start pose
    assert sc.truth_frames[-1].in_view < 0.6


def test_tracking_holds_at_3_fps_with_two_generations_a_frame():
    """A loaded machine (issue 10): the vision loop at 3 fps, its 20-ms budget leaving the
    tracking search 2 GA generations a frame. The whole-volume search gets a frame's share for
    each 1/30 s between frames, up to 4 (it spread over seven, its answer 2 s old), its answer
    is measured again on the newest frame before it counts, then tracked to the end; never a
    false track. (Before: found 23 % in these 10 s, 58 % in 20 s, 5 false tracks.)"""
    cfg = load_config(overrides=["sim.camera_fps=3", "tracker.generations_per_frame=2", "servo.settle_s=4.0"])
    sc = run_lockstep(cfg, 10.0, seed=0)
    s = sc.summary()
    first = next(i for i, f in enumerate(sc.truth_frames) if f.status == "tracking")
    after = [f.status for f in sc.truth_frames[first:]]
    assert first <= 3 and after.count("tracking") >= 0.85 * len(after) and s["found_ratio"] >= 0.8, (after, s)
    assert s["false_tracks"] == 0 and s["track_error_mm"]["p95"] <= 45.0, s
    assert sc.truth_frames[first].error_mm <= 20.0, s  # the confirmed answer, not the 2-s-old one
    # the servo law got it when the frame's processing ended, not before the frame was taken
    assert sc.truth_frames[first].t <= s["first_track_s"] <= sc.truth_frames[first].t + 1.0, s


def test_under_load_a_creature_drifting_out_of_view_is_out_of_view_not_lost():
    """A loaded machine (issue 10): 3 fps, one GA generation a frame, the arm still. The first
    track's velocity is measured from the whole-volume search's answer and its confirmation on a
    newer frame, so the track keeps up with the drift and its prediction leaves the view with
    the creature: out_of_view (the search pose can start), never a pose far from it. Before: the
    track started at rest, coasted 95 mm off the creature (5 false tracks) and then stayed
    `lost` after the creature had left the view."""
    cfg = load_config(overrides=["sim.camera_fps=3", "tracker.generations_per_frame=1"])
    sc = run_lockstep(cfg, 8.0, no_motion=True, seed=0)
    s = sc.summary()
    assert s["final_status"] == "out_of_view" and s["false_tracks"] == 0, s
    gone = [f for f in sc.truth_frames if f.in_view < 0.2]
    assert gone and all(f.status == "out_of_view" for f in gone), [(f.t, f.status, f.in_view) for f in sc.truth_frames]
    assert sum(f.status == "tracking" for f in sc.truth_frames if f.in_view >= 0.6) >= 3, s


def test_the_summary_says_when_a_busy_machine_may_have_cost_the_track():
    """`track` without --json: one line when under half the frames found the creature while the
    load average exceeded the CPU count and the first track came late (after the estimate age
    cap) or never; nothing when the run found it, the machine was not busy, or the first track
    came promptly (a creature drifting out of a still arm's view, `--no-motion`)."""
    from photoservo.cli.track import _busy_note

    run = {"found_ratio": 0.03, "first_track_s": 2.87, "load_average": 9.3}
    note = _busy_note(run, cpus=2, late_s=1.0)
    assert note is not None and "load average 9.3 on 2 CPUs" in note and "came 2.9 s into the session" in note
    assert "never came" in _busy_note({**run, "first_track_s": None}, cpus=2, late_s=1.0)
    assert _busy_note({**run, "found_ratio": 0.98}, cpus=2, late_s=1.0) is None
    assert _busy_note({**run, "load_average": 1.5}, cpus=2, late_s=1.0) is None
    assert _busy_note({**run, "found_ratio": 0.23, "first_track_s": 0.7}, cpus=2, late_s=1.0) is None
    assert "\n" not in note
