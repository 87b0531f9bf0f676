"""Recording cost per encoding (issue 6 item 7): 640x480 stereo at 30 fps.

For each frame encoding of `record.recorder` (lossless = raw pixels + rerun's LZ4, png,
preview JPEG) and two kinds of
frames (the synthetic renderer's water scene as rendered, and the same with 2.5 DN sensor noise
like a real camera), it records N stereo frames through `Recorder` and reports:

  loop ms/frame    median time the calling loop spends in `log_frame` (png/preview encode on
                   a worker thread: a copy + queue hand-off, unless the queue is full because
                   the encoder cannot keep up — then the loop waits)
  total ms/frame   wall time from the first frame to the file closed, per frame (the CPU the
                   recording really costs, whichever thread pays it)
  cpu ms/frame     CPU time of the whole process (every thread, rerun's own compression and
                   writing included) per frame: the honest cost on a loaded machine
  encode ms/frame  time spent encoding one stereo frame (both images)
  MB/min           file size per minute of 30 fps stereo
  read fps         `reader.iter_frames` read-back speed (stereo frames/s, decoded)
  exact            frames read back bit-equal to those logged
and the per-frame cost of the other logs of a tracking frame (estimate with projected points,
timings, 17 arm samples of a 500 Hz control loop), and the stall at a segment change.

Prints a table and writes benchmarks/out/recording.json (median of `--repeats` runs).
Run: python benchmarks/recording.py [--frames 150] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from photoservo.fileio import write_text_atomic
from photoservo.config import load_config
from photoservo.record.recorder import MODES, Recorder
from photoservo.record.reader import iter_frames
from photoservo.vision.photo_model import build_photo_model
from photoservo.sim.specimens import specimen
from photoservo.sim.renderer import (
    CameraEffects,
    Scene,
    calm_water,
    floater_from_model,
    lying_on_water,
    render_stereo,
    synthetic_rig,
)

FPS = 30.0
DISTINCT = 8  # distinct rendered stereo frames, cycled (rendering is slower than recording)


def render_frames(noise_sigma: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Stereo frames of a squid on moving water seen from 600 mm above, camera looking down."""
    photo = specimen("squid", 0)
    model = build_photo_model(photo, load_config().photo_model)
    rig = synthetic_rig()
    scene = Scene(water=calm_water(3), target=floater_from_model(
        photo, model, model.size_px[0] / 180.0, lying_on_water(np.zeros(3), 0.4)))
    fx = CameraEffects(noise_sigma=noise_sigma)
    rng = np.random.default_rng(0)
    out = []
    for k in range(DISTINCT):
        T = np.eye(4)
        T[:3, :3] = np.diag([1.0, -1.0, -1.0])
        T[:3, 3] = (50.0 + 3 * k, -20.0, 600.0)
        out.append(render_stereo(scene, rig, T, t=k / FPS, rng=rng, effects=(fx, fx)))
    return out


def run_once(frames: list, mode: str, n: int, folder: Path) -> dict:
    path = folder / f"bench_{mode}.rrd"
    loop = []
    c0, t0 = time.process_time(), time.perf_counter()
    with Recorder.open(path, "bench", mode=mode) as rec:
        for k in range(n):
            left, right = frames[k % len(frames)]
            t1 = time.perf_counter()
            rec.log_frame(k, k / FPS, left, right)
            loop.append(time.perf_counter() - t1)
    total, cpu = time.perf_counter() - t0, time.process_time() - c0
    size = path.stat().st_size
    t2 = time.perf_counter()
    exact, count = True, 0
    for f in iter_frames(path):
        left, right = frames[f.index % len(frames)]
        exact &= bool(np.array_equal(f.left, left) and np.array_equal(f.right, right))
        count += 1
    read = time.perf_counter() - t2
    path.unlink()
    return {"loop_ms": 1e3 * statistics.median(loop), "total_ms": 1e3 * total / n,
            "cpu_ms": 1e3 * cpu / n,
            "encode_ms": 1e3 * rec.encode_s / n, "mb_per_min": size / 1e6 / (n / FPS) * 60,
            "read_fps": count / read, "exact": exact and count == n}


def other_costs(folder: Path, n: int = 300) -> dict:
    """Per-call cost of the non-image logs of one tracking frame: log_estimate (with the
    projected points of a 1500-point model), log_timings (5 stages), and 17 log_arm calls
    (500 Hz control at 30 fps) whose flush happens in the next log_frame."""
    from photoservo.vision.fitness import project_model
    photo = specimen("squid", 0)
    model = build_photo_model(photo, load_config().photo_model)
    rig = synthetic_rig()
    proj = project_model(np.eye(3), np.array([0.0, 0.0, 600.0]), 2.0, model, rig)
    small = np.zeros((8, 8, 3), np.uint8)
    est, arm, frame = [], [], []
    with Recorder.open(folder / "costs.rrd", "bench") as rec:
        for k in range(n):
            t = k / FPS
            t0 = time.perf_counter()
            for j in range(17):
                rec.log_arm(t + j / 500, np.full(7, 0.1), np.full(7, 0.1), np.full(7, 0.1))
            t1 = time.perf_counter()
            rec.log_frame(k, t, small, small)      # tiny frames: this is the arm flush + metadata
            t2 = time.perf_counter()
            rec.log_estimate(k, t, found=True, fitness=0.8, R=np.eye(3), position_mm=[0, 0, 600.0],
                             alpha=2.0, size_mm=model.size_mm(2.0), projection=proj)
            rec.log_timings(t, {"capture": 1.0, "ga": 20.0, "control": 0.5, "record": 2.0, "total": 25.0})
            t3 = time.perf_counter()
            arm.append((t1 - t0) / 17)
            frame.append(t2 - t1)
            est.append(t3 - t2)
    return {"log_arm_us": 1e6 * statistics.median(arm),
            "arm_flush_and_frame_meta_ms": 1e3 * statistics.median(frame),
            "log_estimate_and_timings_ms": 1e3 * statistics.median(est),
            "points_per_camera": len(model.inner_uv) + len(model.outer_uv)}


def rotation_stall(frames: list, folder: Path, n: int = 120) -> dict:
    """log_frame time at a segment change (flush, footer, rename, new file) vs the median,
    with 1 s segments of lossless frames."""
    times = []
    with Recorder.open(folder / "rot.rrd", "bench", segment_s=1.0) as rec:
        for k in range(n):
            t0 = time.perf_counter()
            rec.log_frame(k, k / FPS, *frames[k % len(frames)])
            times.append(time.perf_counter() - t0)
            time.sleep(max(0.0, 1 / FPS - (time.perf_counter() - t0)))
    at = [times[k] for k in range(1, n) if k % int(FPS) == 0]
    return {"rotation_ms": 1e3 * statistics.median(at), "rotation_max_ms": 1e3 * max(at),
            "other_frames_ms": 1e3 * statistics.median(times)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for scene, sigma in (("synthetic", 0.0), ("synthetic+noise2.5", 2.5)):
            frames = render_frames(sigma)
            for mode in MODES:
                runs = [run_once(frames, mode, args.frames, Path(tmp)) for _ in range(args.repeats)]
                row = {"scene": scene, "mode": mode,
                       **{k: statistics.median(r[k] for r in runs) for k in runs[0] if k != "exact"},
                       "exact": all(r["exact"] for r in runs)}
                results.append(row)
        costs = other_costs(Path(tmp))
        costs.update(rotation_stall(frames, Path(tmp)))
    head = f"{'frames':20s} {'mode':9s} {'loop ms':>8s} {'total ms':>9s} {'cpu ms':>7s} {'enc ms':>7s} {'MB/min':>8s} {'read fps':>9s} exact"
    print(f"Recording 640x480 stereo @ {FPS:.0f} fps, {args.frames} frames x {args.repeats} runs (median); "
          f"{os.cpu_count()} CPUs, machine shared with other engineers (loaded)")
    print(head)
    for r in results:
        print(f"{r['scene']:20s} {r['mode']:9s} {r['loop_ms']:8.2f} {r['total_ms']:9.2f} {r['cpu_ms']:7.2f} {r['encode_ms']:7.2f} "
              f"{r['mb_per_min']:8.0f} {r['read_fps']:9.1f} {'yes' if r['exact'] else 'NO'}")
    print(f"per frame besides the images: log_estimate + log_timings {costs['log_estimate_and_timings_ms']:.2f} ms "
          f"({costs['points_per_camera']} model points per camera), 17 x log_arm "
          f"{costs['log_arm_us']:.1f} us each + their flush with the frame metadata "
          f"{costs['arm_flush_and_frame_meta_ms']:.2f} ms")
    print(f"segment change (lossless, noisy frames, paced at {FPS:.0f} fps): log_frame takes "
          f"{costs['rotation_ms']:.1f} ms (max {costs['rotation_max_ms']:.1f}) vs "
          f"{costs['other_frames_ms']:.1f} ms otherwise")
    out = Path(__file__).parent / "out" / "recording.json"
    write_text_atomic(out, json.dumps({"fps": FPS, "size": [640, 480], "frames": args.frames,
                                       "repeats": args.repeats, "load_note": "shared 2-core machine, loaded",
                                       "results": results, "other_costs": costs}, indent=1) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
