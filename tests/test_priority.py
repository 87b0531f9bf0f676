"""robot/clock.py: `lower_priority` (the session's work that can wait steps back, the loops that
must hold their period, kept ids, do not; run in a child process: niceness cannot be lowered
again without privilege, so the test process itself must not be touched) and `freeze_heap`
(the control loop's collections leave the imported libraries alone)."""

import json
import subprocess
import sys
import textwrap


def test_lower_priority_nices_this_process_and_its_children_but_not_the_kept_ones():
    script = textwrap.dedent("""
        import json, os, subprocess, sys, threading, time
        from photoservo.robot.clock import lower_priority
        sleep = [sys.executable, "-c", "import time; time.sleep(30)"]
        kept, other = subprocess.Popen(sleep), subprocess.Popen(sleep)
        worker_ready, stop = threading.Event(), threading.Event()
        tid = {}
        def work():
            tid["worker"] = threading.get_native_id(); worker_ready.set(); stop.wait()
        threading.Thread(target=work, daemon=True).start()
        worker_ready.wait()
        time.sleep(0.2)  # the children have started
        nice = lambda i: os.getpriority(os.PRIO_PROCESS, i)
        base = nice(0)
        done = lower_priority(base + 5, keep={kept.pid})
        print(json.dumps({"done": done, "base": base, "main": nice(threading.get_native_id()), "worker": nice(tid["worker"]),
                          "kept": nice(kept.pid), "other": nice(other.pid)}))
        for p in (kept, other):
            p.kill(); p.wait()
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    base = got["base"]
    # the kernel clamps nice at 19: a suite started at nice 15 or more asks for 20 and gets 19
    assert got["main"] == got["worker"] == got["other"] == min(base + 5, 19), got
    assert got["kept"] == base, got
    assert got["done"].startswith(f"nice {base + 5} for ") and "of 2 processes" in got["done"], got


def test_freeze_heap_leaves_the_loops_collections_only_what_it_allocates_since():
    """The control process freezes what it imported before its loop (robot/clock.freeze_heap):
    a full collection then scans only the objects made since, not numpy's and numba's."""
    import gc

    from photoservo.robot.clock import freeze_heap

    try:
        frozen = freeze_heap()
        assert frozen == gc.get_freeze_count() > 10_000  # pytest, numpy, photoservo: all frozen
        since = [[k] for k in range(100)]  # the loop's own allocations
        tracked = len(gc.get_objects())  # what a full collection would scan now
        assert 100 <= tracked < frozen // 20, (tracked, frozen)
        assert since[0] in gc.get_objects()
    finally:
        gc.unfreeze()
    assert gc.get_freeze_count() == 0
