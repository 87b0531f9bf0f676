"""Where a recording lives and what made it (issue 13): its default name, the `rerun` CLI's
footer check, the software versions a replay compares against."""

from __future__ import annotations

import platform
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from photoservo.record.layout import rr


def default_path(verb: str, logs_dir: str | Path = "logs", now: datetime | None = None) -> Path:
    """`logs/<UTC timestamp>_<verb>.rrd`, e.g. logs/20261122T043700Z_track.rrd (`_2`, `_3`, ...
    appended when that name is taken)."""
    now = now or datetime.now(UTC)
    stem = f"{now.strftime('%Y%m%dT%H%M%SZ')}_{verb}"
    p = Path(logs_dir) / f"{stem}.rrd"
    n = 2
    while p.exists():
        p, n = Path(logs_dir) / f"{stem}_{n}.rrd", n + 1
    return p


def rerun_cli() -> Path:
    """The `rerun` executable the rerun-sdk wheel installs beside this Python."""
    return Path(sys.executable).parent / "rerun"


def verify_rrd(path: str | Path, timeout_s: float = 120.0) -> tuple[bool, str]:
    """Run `rerun rrd verify PATH` (footer check on): (passed, the CLI's last output line)."""
    r = subprocess.run([str(rerun_cli()), "rrd", "verify", str(path)], check=False,
                       capture_output=True, text=True, timeout=timeout_s)
    lines = [s for s in (r.stdout + r.stderr).splitlines() if s.strip()]
    return r.returncode == 0, (lines[-1] if lines else "")


def software_versions() -> dict[str, str]:
    """Versions that decide whether a replay can reproduce a run."""
    import cv2

    from photoservo import __version__
    return {"photoservo": __version__, "python": platform.python_version(),
            "numpy": np.__version__, "opencv": cv2.__version__, "rerun": rr.__version__}
