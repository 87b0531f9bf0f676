"""photoservo find-cameras [SOURCE ...] [--max-index N] [--snapshots DIR | --no-snapshots] [--json]

Lists what OpenCV can open here: camera indices 0..N-1, the /dev/video* nodes, and any SOURCE
given (a device path or a video file), each with its resolution, frame rate, FOURCC and backend,
and saves one snapshot of each (DIR/<source>.png, default logs/find-cameras/) to tell which
camera is which. Give the indices or paths to `calibrate capture --devices L R` and
`track --cameras L R`.

Exit status: 0 at least one source delivered a frame, 1 none did, 2 bad input.

Examples:
    photoservo find-cameras
    photoservo find-cameras /dev/video4 left.mp4 --snapshots cams/
    photoservo find-cameras --max-index 4 --no-snapshots --json
"""

from __future__ import annotations

import argparse
import logging
import re
from pathlib import Path

from photoservo.cli.options import bounded
from photoservo.cli.output import print_json
from photoservo.errors import EXIT_NOT_FOUND, EXIT_OK
from photoservo.fileio import write_image_atomic

log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sources", nargs="*", metavar="SOURCE", help="also try these device paths or video files")
    p.add_argument("--max-index", type=bounded(int, 0, 64), default=10, metavar="N",
                   help="try camera indices 0..N-1 (default 10)")
    snap = p.add_mutually_exclusive_group()
    snap.add_argument("--snapshots", metavar="DIR", default="logs/find-cameras",
                      help="folder for one PNG per source (default logs/find-cameras)")
    snap.add_argument("--no-snapshots", action="store_true", help="write no snapshot")
    p.add_argument("--json", action="store_true", help="print the list as JSON on stdout")


def _snapshot_name(device: int | str) -> str:
    return "index" + str(device) if isinstance(device, int) else re.sub(r"[^A-Za-z0-9._-]+", "_", str(device)).strip("_")


def run(args: argparse.Namespace) -> int:
    from photoservo.vision.devices import find_cameras

    cams = find_cameras(args.max_index, tuple(args.sources))
    rows = []
    for c in cams:
        png = None
        if c.frame is not None and not args.no_snapshots:
            png = Path(args.snapshots) / f"{_snapshot_name(c.device)}.png"
            write_image_atomic(png, c.frame)
        rows.append((c, png))
    if args.json:
        print_json([{"device": c.device, "backend": c.backend, "width": c.width, "height": c.height, "fps": c.fps,
                     "fourcc": c.fourcc, "delivers_frames": c.frame is not None,
                     "snapshot": None if png is None else str(png)} for c, png in rows])
    else:
        for c, png in rows:
            print(c.describe() + (f"; snapshot {png}" if png else ""))
        if not rows:
            print(f"no camera or video source opened (tried indices 0..{args.max_index - 1}, /dev/video*"
                  f"{', ' + ', '.join(args.sources) if args.sources else ''})")
    return EXIT_OK if any(c.frame is not None for c, _ in rows) else EXIT_NOT_FOUND
