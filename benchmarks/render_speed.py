"""Render speed of the simulated stereo cameras (`photoservo track --sim`): the exact render
against render_view's fast path (water shaded per stride x stride block, target at full
resolution, tiled sensor noise), measured in the same run.

Scene: the simulator's own (SimScene with the default [sim] config: squid, 2 px/mm, noise 2 DN),
the left camera 600 mm above the drifting target looking down with a 15 deg tilt, a new target
pose and camera pose every frame (as in tracking). Per stride: ms per stereo frame (2 x 640x480),
wall median and CPU (process time, all threads) median over the repeats; the strides run
interleaved frame by frame so each sees the same machine load. Also timed: SimScene.render (what
the simulator calls; fast path). Quality of each fast stride against the exact render of the
same frame: IoU of the target-hue masks, mean |difference| of the water's mean colour (DN) and
the count of near-white glint pixels.

The machine has 2 cores shared with other jobs: the load average is stored; wall times are
pessimistic, the CPU column is the steadier one; the ratio is what carries over.

Prints a table and writes benchmarks/out/render_speed.json.
Run: python benchmarks/render_speed.py [--frames 15] [--strides 2,4,8]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import cv2
import numpy as np

from photoservo.fileio import write_text_atomic
from photoservo.config import load_config
from photoservo.sim.world import SIM_WATER_STRIDE, SimScene
from photoservo.vision.photo_model import NO_HUE, hue_image
from photoservo.sim.renderer import CameraEffects, make_transform
from photoservo.sim.scenes import synthetic_rig

OUT = Path(__file__).parent / "out" / "render_speed.json"


def camera_pose(sim: SimScene, t: float) -> np.ndarray:
    """T_base_left: 600 mm above the target at time t, looking down, tilted 15 deg, slowly yawing."""
    c, s = np.cos(0.2 * t), np.sin(0.2 * t)
    yaw = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    tilt, _ = cv2.Rodrigues(np.array([np.radians(15.0), 0.0, 0.0]))
    R = yaw @ np.diag([1.0, -1.0, -1.0]) @ tilt
    target = sim.motion.pose(t)[:3, 3]
    return make_transform(R, target - R @ np.array([0.0, 0.0, 600.0]))


def quality(exact: np.ndarray, fast: np.ndarray, target_hues: np.ndarray, pm) -> dict:
    def hue_mask(img):
        hue = hue_image(img, pm.min_saturation, pm.min_value)
        return hue, (hue != NO_HUE) & target_hues[np.minimum(hue, 179)]

    hue_e, me = hue_mask(exact)
    _, mf = hue_mask(fast)
    objects = (hue_e == NO_HUE) | me | mf
    water = ~cv2.dilate(objects.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    return {"target_iou": float((me & mf).sum() / max(1, (me | mf).sum())),
            "water_mean_diff_dn": float(np.abs(exact[water].mean(0) - fast[water].mean(0)).max()),
            "glint_px_exact": int((exact.min(-1) > 220).sum()), "glint_px_fast": int((fast.min(-1) > 220).sum())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=15, help="timed frames per stride")
    ap.add_argument("--strides", default="2,4,8", help="fast-path water strides to compare with the exact render")
    args = ap.parse_args()
    strides = [1] + [int(s) for s in args.strides.split(",")]
    cfg = load_config()
    sim = SimScene(cfg.sim, cfg.photo_model, synthetic_rig())
    r = sim.renderer
    fx = (CameraEffects(noise_sigma=2.0),) * 2

    def stereo(t: float, stride: int):
        T_world_left = sim.T_world_base @ camera_pose(sim, t)
        return r.render(sim.scene(t), T_world_left, t, np.random.default_rng([int(1e3 * t), 5]), fx,
                        water_stride=stride)

    for s in strides:  # warm-up: numba compile/cache load, coarse rays, noise tile
        stereo(0.0, s)
    sim.render(camera_pose(sim, 0.0), 0.0, camera_pose(sim, 0.0), 0.001)
    wall = {s: [] for s in strides}
    cpu = {s: [] for s in strides}
    wall_sim, cpu_sim = [], []
    qual = {s: [] for s in strides[1:]}
    load0 = os.getloadavg()
    for i in range(args.frames):
        t = 0.1 + i / 30.0
        imgs = {}
        for s in strides:
            w0, c0 = time.perf_counter(), time.process_time()
            imgs[s] = stereo(t, s)
            wall[s].append(time.perf_counter() - w0)
            cpu[s].append(time.process_time() - c0)
        w0, c0 = time.perf_counter(), time.process_time()
        sim.render(camera_pose(sim, t), t, camera_pose(sim, t + 0.001), t + 0.001)
        wall_sim.append(time.perf_counter() - w0)
        cpu_sim.append(time.process_time() - c0)
        for s in strides[1:]:
            for e, f in zip(imgs[1], imgs[s]):
                qual[s].append(quality(e, f, sim.model.target_hues, cfg.photo_model))
    rows = []

    def ms(v: list[float]) -> float:
        return 1e3 * float(np.median(v))

    for s in strides:
        row = {"path": "exact" if s == 1 else "fast", "water_stride": s, "wall_ms_per_stereo": ms(wall[s]),
               "cpu_ms_per_stereo": ms(cpu[s]), "wall_speedup": ms(wall[1]) / ms(wall[s]),
               "cpu_speedup": ms(cpu[1]) / ms(cpu[s])}
        if s > 1:
            q = qual[s]
            row.update({"target_iou_min": min(x["target_iou"] for x in q),
                        "water_mean_diff_dn_max": max(x["water_mean_diff_dn"] for x in q),
                        "glint_px_ratio_median": float(np.median([x["glint_px_fast"] / max(1, x["glint_px_exact"])
                                                                  for x in q]))})
        rows.append(row)
    sim_row = {"path": f"SimScene.render (stride {SIM_WATER_STRIDE})", "wall_ms_per_stereo": ms(wall_sim),
               "cpu_ms_per_stereo": ms(cpu_sim)}
    result = {"frames": args.frames, "image": "2 x 640x480", "rows": rows, "sim_scene_render": sim_row,
              "loadavg_start": list(load0), "loadavg_end": list(os.getloadavg()), "cpu_count": os.cpu_count(),
              "note": "2-core machine shared with other jobs: wall times are pessimistic; compare within this run"}
    print(f"render speed, ms per stereo frame (median of {args.frames}; load average {load0[0]:.1f} -> "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores, shared)")
    print(f"{'path':<28}{'wall ms':>9}{'cpu ms':>9}{'x wall':>8}{'x cpu':>7}{'IoU min':>9}{'water dDN':>10}{'glints':>8}")
    for row in rows:
        name = "exact" if row["water_stride"] == 1 else f"fast, water stride {row['water_stride']}"
        q = (f"{row['target_iou_min']:>9.3f}{row['water_mean_diff_dn_max']:>10.2f}{row['glint_px_ratio_median']:>8.2f}"
             if row["water_stride"] > 1 else "")
        print(f"{name:<28}{row['wall_ms_per_stereo']:>9.1f}{row['cpu_ms_per_stereo']:>9.1f}"
              f"{row['wall_speedup']:>8.1f}{row['cpu_speedup']:>7.1f}{q}")
    print(f"{sim_row['path']:<28}{sim_row['wall_ms_per_stereo']:>9.1f}{sim_row['cpu_ms_per_stereo']:>9.1f}")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(OUT, json.dumps(result, indent=2) + "\n")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
