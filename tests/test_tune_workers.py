"""`photoservo tune` workers (issue 14), as real processes: two workers share a study on a real
PostgreSQL server started here (no trial lost or run twice, both work); SIGTERM stops after the
running trial, exit 143, and the same command continues the study to its budget."""

from __future__ import annotations

import glob
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
# tiny worlds: 0.6 s at 5 fps (3 frames), hold scored after 0.3 s
TINY = ["--space", "servo.k_position=0.5:4:log", "--duration", "0.6", "--settle", "0.3",
        "--set", "sim.camera_fps=5"]


def _tune(*argv: str, **kw) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.Popen([sys.executable, "-m", "photoservo.cli", "tune", *argv], env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kw)


def _trials(storage: str, study: str) -> list:
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    try:
        return optuna.load_study(study_name=study, storage=storage).get_trials(deepcopy=False)
    except KeyError:   # not created yet
        return []


def _wait_for(ready, proc: subprocess.Popen, timeout: float = 300.0) -> None:
    """Poll `ready()` until true, the process has ended, or `timeout` s have passed."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None and not ready():
        time.sleep(0.05)


def _pg_bin() -> Path | None:
    """The PostgreSQL server binaries: on PATH, or Debian's /usr/lib/postgresql/<v>/bin."""
    found = shutil.which("initdb")
    if found:
        return Path(found).resolve().parent
    dirs = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"))
    return Path(dirs[-1]).parent if dirs else None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def postgres() -> Iterator[str]:
    """A real PostgreSQL server in a temporary cluster (trust auth, TCP on 127.0.0.1), run as the
    unprivileged 'postgres' user when we are root (the server refuses root). CI must have it
    (.ci/run installs Debian's postgresql): there the test fails instead of skipping."""
    pg = _pg_bin()
    if pg is None:
        if os.environ.get("CI"):
            pytest.fail("PostgreSQL server binaries (initdb) not found: .ci/run should install postgresql")
        pytest.skip("PostgreSQL server binaries (initdb) not installed")
    as_user: list[str] = []
    data = Path(tempfile.mkdtemp(prefix="photoservo-pg-"))
    if os.geteuid() == 0:
        import pwd

        user = pwd.getpwnam("postgres")
        os.chown(data, user.pw_uid, user.pw_gid)
        as_user = ["runuser", "-u", "postgres", "--"]
    port = _free_port()
    run = lambda *cmd: subprocess.run([*as_user, *cmd], check=True, capture_output=True, text=True)  # noqa: E731
    try:
        run(str(pg / "initdb"), "-D", str(data / "db"), "-A", "trust", "-U", "postgres", "--no-sync")
        run(str(pg / "pg_ctl"), "-D", str(data / "db"), "-w", "-l", str(data / "server.log"), "-o",
            f"-p {port} -k {data} -c listen_addresses=127.0.0.1 -c fsync=off", "start")
        yield f"postgresql://postgres@127.0.0.1:{port}/postgres"
    finally:
        subprocess.run([*as_user, str(pg / "pg_ctl"), "-D", str(data / "db"), "-m", "fast", "-w", "stop"],
                       capture_output=True)
        shutil.rmtree(data, ignore_errors=True)


def test_two_workers_share_a_postgresql_study(postgres: str):
    """Two worker processes (as two cluster nodes would run it, each its own --seed) share one
    study on the server: 4 trials complete, numbered 0..3, none FAILed, PRUNED or run twice
    (but for an empty placeholder past the budget, below), and both workers ran trials."""
    common = [*TINY, "--worlds", "1", "--trials", "4", "--storage", postgres, "--study", "pg"]
    first = _tune(*common, "--seed", "0")
    # The first node creates the study and starts running its first trial; it is held there
    # (SIGSTOP, well within the storage's 60 s heartbeat grace) until the second node has joined
    # and started one of its own, then released. Without the hold the first node could use the
    # whole budget while the second was still starting (imports, compiled kernels): it did in CI.
    _wait_for(lambda: any(t.user_attrs.get("worker") for t in _trials(postgres, "pg")), first)   # in its run
    first.send_signal(signal.SIGSTOP)
    try:
        second = _tune(*common, "--seed", "1")
        second_name = f"{socket.gethostname()}:{second.pid}"
        _wait_for(lambda: any(t.user_attrs.get("worker") == second_name for t in _trials(postgres, "pg")),
                  second, timeout=45.0)
    finally:
        first.send_signal(signal.SIGCONT)
    outs = [p.communicate(timeout=600) for p in (first, second)]
    assert first.returncode == 0 and second.returncode == 0, [o[1][-2000:] for o in outs]
    trials = _trials(postgres, "pg")
    # Two workers that end their trials at the same moment both see 3 of 4 used and both take a
    # new trial number; the later one finds the budget used and prunes its trial before it
    # suggests or measures anything (`run_worker`'s guard): such a placeholder is allowed, nothing else.
    placeholders = [t for t in trials if t.state.name == "PRUNED" and not t.params and not t.user_attrs]
    assert all(t.number >= 4 for t in placeholders)
    trials = [t for t in trials if t not in placeholders]
    assert [t.number for t in trials] == [0, 1, 2, 3]
    assert [t.state.name for t in trials] == ["COMPLETE"] * 4
    assert len({t.user_attrs["worker"] for t in trials}) == 2
    assert trials[0].user_attrs.get("start") and len({t.params["servo.k_position"] for t in trials}) == 4
    assert all(t.user_attrs["scores"]["hold"] > 0 for t in trials)


def test_sigterm_stops_after_the_running_trial_and_the_study_resumes(tmp_path: Path):
    db = str(tmp_path / "t.db")
    url = f"sqlite:///{db}"
    argv = [*TINY, "--worlds", "1", "--trials", "3", "--storage", db, "--study", "s"]
    p = _tune(*argv)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(p.stderr), daemon=True)   # the child's stderr
    reader.start()
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and p.poll() is None and not any(x.startswith("trial 1/3") for x in lines):
        time.sleep(0.2)   # the first trial is stored (the progress line follows the storage's tell)
    p.send_signal(signal.SIGTERM)
    p.wait(timeout=300)
    reader.join(timeout=10)
    err = "".join(lines)
    assert p.returncode == 128 + signal.SIGTERM, err[-2000:]
    assert "photoservo tune: interrupted by SIGTERM: stopped after the running trials" in err
    kept = _trials(url, "s")
    assert {t.state.name for t in kept} == {"COMPLETE"} and 1 <= len(kept) < 3   # none left running
    again = _tune(*argv)
    out, err = again.communicate(timeout=600)
    assert again.returncode == 0, err[-2000:]
    trials = _trials(url, "s")
    assert [t.state.name for t in trials] == ["COMPLETE"] * 3
    assert [t.params for t in trials[: len(kept)]] == [t.params for t in kept]   # the kept ones, not re-run
    assert f"{len(kept)}/3 trials done" in err
