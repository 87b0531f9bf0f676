"""photoservo scan --rig RIG.toml --photo PHOTO [--roi X,Y,W,H] --left L.png --right R.png
                --pose POSE.json --out DIR [--axes x,y,z,rx,ry,rz] [--steps N] [--span-mm MM]
                [--span-deg DEG] [--alpha-factor K] [--config CFG.toml] [--set key=value ...]

Fitness distribution scans (the paper's fitness maps, vision/scan.py): the stereo fitness over
(pose axis x alpha) slices through the pose in POSE.json (a ground truth or an estimate), one
labelled heatmap PNG per axis in DIR (scan_<axis>.png) plus scan.json with the grids. Prints the
peak of each map; a progress bar goes to stderr (on a terminal).

Examples:
    photoservo scan --rig examples/scene/rig.toml --photo examples/scene/photo.png \\
        --left examples/scene/left.png --right examples/scene/right.png --pose examples/scene/truth.json \\
        --out scans/ --axes z,ry --steps 41
    photoservo scan --rig rig.toml --photo squid.png --left left.png --right right.png \\
        --pose truth.json --out scans/
"""

from __future__ import annotations

import argparse
from pathlib import Path

from photoservo.errors import InputError
from photoservo.fileio import write_image_atomic, write_text_atomic
from photoservo.cli.options import add_config_options, bounded
from photoservo.cli.output import dumps_strict, progress
from photoservo.cli.options import add_stereo_inputs, load_stereo_inputs
from photoservo.config import load_config
from photoservo.vision.fitness import stereo_hue
from photoservo.vision.scan import AXES, draw_slice, load_pose, scan_slice


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_stereo_inputs(p)
    p.add_argument("--pose", required=True, metavar="POSE.json", help="estimate or ground-truth JSON to scan around")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for scan_<axis>.png and scan.json")
    p.add_argument("--axes", default="x,y,z,rx,ry,rz", help="comma-separated axes among " + ",".join(AXES))
    p.add_argument("--steps", type=bounded(int, 3, 401), default=81, help="cells per map side (3..401, default 81)")
    p.add_argument("--span-mm", type=bounded(float, 0.0, 10000.0, lo_open=True, unit="mm"), default=60.0,
                   help="position axes scan +-this (mm, default 60)")
    p.add_argument("--span-deg", type=bounded(float, 0.0, 180.0, lo_open=True, unit="deg"), default=45.0,
                   help="orientation axes scan +-this (deg, default 45)")
    p.add_argument("--alpha-factor", type=bounded(float, 1.0, 100.0, lo_open=True), default=2.0,
                   help="alpha runs from alpha/K to alpha*K, log-spaced (default 2)")
    add_config_options(p)


def run(args: argparse.Namespace) -> int:
    axes = [a.strip() for a in args.axes.split(",") if a.strip()]
    bad = [a for a in axes if a not in AXES]
    if not axes or bad:
        raise InputError(f"--axes '{args.axes}': each must be one of {', '.join(AXES)}")
    cfg = load_config(args.config, args.overrides)
    rig, model, left, right = load_stereo_inputs(args, cfg)
    R0, t0, alpha0 = load_pose(args.pose)
    frame = stereo_hue(left, right, cfg.fitness)

    out = Path(args.out)
    results = []
    with progress(len(axes) * args.steps, "scan", unit="row") as bar:
        for axis in axes:
            bar.set_description(f"scan {axis}")
            span = args.span_mm if AXES[axis][0] == "mm" else args.span_deg
            s = scan_slice(axis, R0, t0, alpha0, model, frame, rig, cfg.fitness, span, args.alpha_factor,
                           args.steps, progress=lambda done, total: bar.update(1))
            png = out / f"scan_{axis}.png"
            write_image_atomic(png, draw_slice(s, f"fitness: {axis} x alpha around {Path(args.pose).name}"))
            results.append((s, png))
    summary = {"pose": {"position_mm": t0.tolist(), "rotation": R0.tolist(), "alpha_px_per_mm": alpha0},
               "maps": []}
    for s, png in results:
        d, a, f = s.peak()
        print(f"{s.axis:>2}: peak fitness {f:.3f} at {s.axis} {d:+.1f} {s.unit}, alpha {a:.4g} px/mm "
              f"(given alpha {alpha0:.4g})  -> {png}")
        summary["maps"].append({"axis": s.axis, "unit": s.unit, "png": str(png),
                                "peak": {"offset": d, "alpha_px_per_mm": a, "fitness": f},
                                "offsets": s.offsets.tolist(), "alphas": s.alphas.tolist(),
                                "fitness": s.fitness.round(5).tolist()})
    write_text_atomic(out / "scan.json", dumps_strict(summary))
    return 0
