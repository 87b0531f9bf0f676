"""The link-quality gate: its bookkeeping (pure) and the gate on a real pty with the emulator."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from photoservo.robot import protocol as P
from photoservo.robot.link import Link, LinkError, LinkQualityError
from photoservo.robot.link_quality import BAD, REFUSED, WATCHDOG, QualityWindow, report_events
from photoservo.sim.emulator import Emulator
from test_link import emu_params, hold, link_params, wait_for


def _report(rx_crc_errors: int, status: P.Status) -> P.StateReport:
    return P.StateReport(0, 0, 0, 0, int(status), 0, rx_crc_errors, (0.0,) * 7, (0.0,) * 7)


def test_window_counts_rates_and_forgets_old_events():
    w = QualityWindow(0.5)
    w.add(0.0, BAD, 3)
    w.add(0.2, REFUSED)
    w.add(0.4, WATCHDOG)
    q = w.snapshot(0.45)
    assert (q.bad_frames_per_s, q.refused_per_s, q.watchdog_per_s) == (6.0, 2.0, 2.0)
    q = w.snapshot(0.6)  # the bad frames at t = 0 left the window; totals keep them
    assert q.bad_frames_per_s == 0.0 and q.bad_frames == 3 and q.refused == 1 and q.watchdog_stops == 1
    assert w.snapshot(2.0).text() == "link ok"
    assert q.over(10.0, 10.0, 10.0) == ""
    assert q.over(10.0, 1.0, 10.0) == "1 refused setpoints (limit 1/s)"


def test_report_events_counts_bridge_crc_growth_with_wrap_and_watchdog_edges():
    a = _report(0xFFFFFFFE, P.Status.SERVO_ON)
    b = _report(3, P.Status.SERVO_ON | P.Status.WATCHDOG)  # the counter wrapped: 5 new bad frames
    c = _report(3, P.Status.SERVO_ON | P.Status.WATCHDOG)  # still latched: not a new stop
    assert report_events(None, a) == (0, 0)
    assert report_events(a, b) == (5, 1)
    assert report_events(b, c) == (0, 0)


def test_advice_tells_a_noisy_line_from_a_starved_host():
    w = QualityWindow(1.0)
    w.add(0.0, WATCHDOG, 6)
    late = w.snapshot(0.1)
    assert "starved" in late.advice(10.0, False)
    w.add(0.0, BAD, 50)
    noisy = w.snapshot(0.1)
    assert "cable" in noisy.advice(10.0, False) and "pa10-sim --drop" in noisy.advice(10.0, True)


@pytest.mark.parametrize("simulated", [False, True])
def test_gate_trips_on_a_noisy_pty_and_still_stops_the_arm(simulated):
    # a clean stream at rest, then 1 % of the bytes dropped and 1 % corrupted each way: the gate
    # raises within 0.5 s, names the counts, and STOP / servo off still get through
    with Emulator(emu_params()) as e, Link(e.path, link_params(gate=True), simulated=simulated) as lk:
        lk.enable()
        lk.wait_state()
        q0 = np.float32(e.true_state().q).astype(float)
        hold(lk, q0, 100)
        assert lk.quality().bad_frames == 0  # (a stalled test thread may make a watchdog stop)
        e.line_faults(drop=0.01, corrupt=0.01)
        t0 = time.monotonic()
        with pytest.raises(LinkQualityError) as ei:
            hold(lk, q0, 750, read_state=True)  # 3 s
        took = time.monotonic() - t0
        msg = str(ei.value)
        assert took < 0.5, took
        assert "bad frames (limit 10/s)" in msg and "since the start" in msg
        assert ("pa10-sim --drop" in msg) == simulated and ("cable" in msg) != simulated
        with pytest.raises(LinkQualityError):  # latched
            lk.state()
        e.line_faults(drop=0.0, corrupt=0.0)
        assert lk.safe_stop() == ""
        assert wait_for(lambda: e.true_state().status & P.Status.BRAKED and not e.model.servo_on)


def test_gate_quiet_on_a_clean_line():
    with Emulator(emu_params()) as e, Link(e.path, link_params(gate=True)) as lk:
        lk.enable()
        lk.wait_state()
        q0 = np.float32(e.true_state().q).astype(float)
        hold(lk, q0, 250, read_state=True)
        q = lk.quality()
        assert q.bad_frames == 0 and q.refused == 0


def test_quality_limits_are_bounded():
    from photoservo.errors import InputError

    for key, v in (("max_bad_frames_per_s", float("inf")), ("max_refused_per_s", -1.0),
                   ("quality_window_s", 0.0), ("max_watchdog_per_s", float("nan"))):
        with pytest.raises(InputError, match=key):
            dataclasses.replace(link_params(gate=True), **{key: v}).validate("link")


def test_non_finite_state_is_never_used_and_counts_as_a_bad_frame():
    # a bridge that reports NaN joints (a firmware fault): the host keeps the last finite state
    # and counts the report against the gate
    with Emulator(emu_params()) as e, Link(e.path, link_params(gate=True)) as lk:
        good = lk.wait_state()
        report = e.model.report
        e.model.report = lambda: dataclasses.replace(report(), q=(float("nan"),) * 7)
        time.sleep(0.3)
        q = lk.quality()
        assert q.bad_frames > 10
        assert all(np.all(np.isfinite(s.q)) for s in lk.history())
        with pytest.raises(LinkError, match="silent|quality gate"):
            lk.state()
        e.model.report = report
        np.testing.assert_allclose(lk.history()[-1].q, good.q, atol=1e-6)
