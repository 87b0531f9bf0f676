"""Recording cost and replay fidelity per recording mode (issue 13): 640x480 stereo at 30 fps.

Size and cost: for each mode (compact with an AV1 video of 10 or 30 frames a second ([recording]
video_fps 10 or 0), an H.264 one, none; full; preview) and three
kinds of frames — the simulator as `track --sim` sees it (the renderer's water scene, cameras
following the drift), the same with 2.5 DN sensor noise, and the second generator's harbour
scenes 0-2 (`sim/harbour.py`: its own water, light, foam and 2-6 DN noise; fresh 2 DN noise per
frame so frames differ as a camera's do; in scene 1 the murky water's noisy hue crosses into
the squid's target hues on a third of the pixels) — it logs N stereo frames through `Recorder`, paced at
30 fps as a session would, each with what `track` logs besides (estimate with projected
points, truth, timings, 17 arm samples of the control loop), and reports:

  MB/min      file size per minute of 30 fps stereo
  loop ms     median time per frame the loop spends in the recorder's calls (compact and
              preview encode on worker threads: the loop copies and queues)
  cpu ms      CPU time per frame of the process and its video encoder process (workers and
              rerun's writer included):
              what recording really costs on a loaded machine
  encode ms   worker time per frame spent encoding planes and video (wall, both workers)

Replay fidelity: one `track --sim --lockstep` session (seeded: the same frames every time) is
recorded in each mode and replayed with tracker / GA / estimator / fitness-weight / servo keys
changed; a mode is BIT-EXACT when every replayed frame's status, fitness, generations, position
and alpha, and every open-loop command, equal those of the full frames' replay ("identical").
Also: the replay with the recorded config reproduces the recorded estimates.

Prints two tables and writes benchmarks/out/recording.json (medians of `--repeats` runs).
Run: python benchmarks/recording.py [--frames 300] [--repeats 3] [--skip-fidelity]
The machine is shared by several engineers: note the load printed with the results.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from photoservo.config import load_config
from photoservo.fileio import write_text_atomic
from photoservo.record import recorder as recorder_module
from photoservo.record.recorder import Recorder
from photoservo.vision.fitness import project_model, stereo_hue

FPS = 30.0
DISTINCT = 45   # distinct stereo frames per kind (1.5 s), cycled
#: (mode, video, video_fps): the default first ([recording] compact, av1 at 10 Hz)
MODES = (("compact", "av1", 10.0), ("compact", "av1", 0.0), ("compact", "h264", 10.0), ("compact", "none", 0.0),
         ("full", "none", 0.0), ("preview", "av1", 10.0))
KEYS = ["ga.population=12", "tracker.generations_per_frame=3", "tracker.gain_position=0.5",
        "estimator.min_contrast=0.6", "fitness.w_outer_mismatch=0.7", "servo.k_position=0.3"]


class Frames:
    """N distinct stereo frames of one kind with what the loop has for them: the fitness input
    (hue planes), a model, a projection of it and a truth pose."""

    def __init__(self, name: str, pairs: list, model, rig, cfg) -> None:
        self.name, self.pairs, self.model = name, pairs, model
        self.hues = [stereo_hue(l, r, cfg.fitness) for l, r in pairs]
        self.proj = project_model(np.eye(3), np.array([0.0, 0.0, 600.0]), 2.0, model, rig)


def sim_frames(cfg, noise: float) -> Frames:
    """The simulator's frames along its drift, as `track --sim` renders them."""
    from photoservo.robot import pa10
    from photoservo.sim.run import build_sim

    sim = build_sim(cfg)
    T0 = pa10.fk(sim.q0) @ sim.rig.T_flange_left()
    rng = np.random.default_rng(0)
    pairs = []
    for k in range(DISTINCT):
        t = k / FPS
        T = T0.copy()
        T[:3, 3] += sim.scene.motion.v * t
        left, right = sim.scene.render(T, t, T, t + cfg.sim.lr_skew_s)
        if noise:
            left, right = (np.clip(im + rng.normal(0, noise, im.shape), 0, 255).astype(np.uint8) for im in (left, right))
        pairs.append((left, right))
    return Frames("sim" + (f"+noise{noise:g}" if noise else ""), pairs, sim.scene.model, sim.rig, cfg)


def harbour_frames(cfg, seed: int) -> Frames:
    """A harbour scene (the second generator) with fresh 2 DN noise per frame."""
    from photoservo.sim import harbour
    from photoservo.vision.photo_model import build_photo_model

    sc = harbour.random_scene(seed, cfg.synthetic, cfg.photo_model, kind="squid")
    rng = np.random.default_rng(seed)
    pairs = [tuple(np.clip(im + rng.normal(0, 2.0, im.shape), 0, 255).astype(np.uint8) for im in (sc.left, sc.right))
             for _ in range(DISTINCT)]
    return Frames(f"harbour {seed}", pairs, build_photo_model(sc.photo, cfg.photo_model), sc.rig, cfg)


def _cpu_s() -> float:
    """CPU seconds of this process and its ended children (the video encoder process)."""
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ch.ru_utime + ch.ru_stime


def run_once(fr: Frames, mode: str, video: str, n: int, folder: Path, cfg, video_fps: float = 0.0) -> dict:
    from photoservo.sim.scenes import synthetic_rig
    from photoservo.tomlconf import dump_config
    from photoservo.vision.rig import dump_rig

    path = folder / f"bench_{mode}_{video}_{video_fps:g}.rrd"
    loop = []
    T = np.eye(4)
    c0, t0 = _cpu_s(), time.perf_counter()
    with Recorder.open(path, "bench", mode=mode, video=video, video_fps=video_fps) as rec:
        rec.log_static_setup(dump_rig(synthetic_rig()), None, fr.model, dump_config(cfg), seed=0)
        for k in range(n):
            j = k % len(fr.pairs)
            t = k / FPS
            t1 = time.perf_counter()
            for i in range(17):
                rec.log_arm(t + i / 500, np.full(7, 0.1), np.full(7, 0.1), np.full(7, 0.01))
            rec.log_frame(k, t, *fr.pairs[j], T_base_left=T, capture_times=(t, t + 0.001), fitness_input=fr.hues[j])
            rec.log_estimate(k, t, found=True, fitness=0.9, R=np.eye(3), position_mm=[0, 0, 600.0], alpha=2.0,
                             size_mm=fr.model.size_mm(2.0), generations=8, T_base_left=T, projection=fr.proj)
            rec.log_truth(k, t, T, fr.model.size_mm(2.0))
            rec.log_timings(t, {"hue": 10.0, "ga": 40.0, "record": 2.0}, frame=k)
            loop.append(time.perf_counter() - t1)
            time.sleep(max(0.0, t0 + (k + 1) / FPS - time.perf_counter()))
    cpu = _cpu_s() - c0
    size = path.stat().st_size
    enc = rec.encoding.encode_s if rec.encoding is not None else 0.0
    path.unlink()
    return {"mb_per_min": size / 1e6 / (n / FPS) * 60, "loop_ms": 1e3 * statistics.median(loop),
            "loop_p90_ms": 1e3 * float(np.percentile(loop, 90)), "cpu_ms": 1e3 * cpu / n,
            "encode_ms": 1e3 * enc / n}


def size_table(n: int, repeats: int) -> list[dict]:
    cfg = load_config()
    kinds = [sim_frames(cfg, 0.0), sim_frames(cfg, 2.5), *(harbour_frames(cfg, s) for s in range(3))]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for fr in kinds:
            for mode, video, vfps in MODES:
                runs = [run_once(fr, mode, video, n, Path(tmp), cfg, vfps) for _ in range(repeats)]
                rows.append({"frames": fr.name, "mode": mode, "video": video, "video_fps": vfps,
                             **{k: statistics.median(r[k] for r in runs) for k in runs[0]}})
                print(f"  {fr.name:14s} {mode:8s} {_video(video, vfps):9s} {rows[-1]['mb_per_min']:7.0f} MB/min",
                      flush=True)
        # rerun's batcher period: a chunk per entity per period, each with its ~2 KB schema
        saved = recorder_module.BATCH_S
        try:
            recorder_module.BATCH_S = 0.2
            r = run_once(kinds[0], "compact", "av1", n, Path(tmp), cfg, 10.0)
        finally:
            recorder_module.BATCH_S = saved
        rows.append({"frames": kinds[0].name, "mode": "compact", "video": "av1", "video_fps": 10.0,
                     "note": "BATCH_S=0.2", **r})
    return rows


def _video(video: str, video_fps: float) -> str:
    """'av1@10' for a video at 10 Hz, 'av1@30' for every frame, 'none'."""
    return video if video == "none" else f"{video}@{video_fps or FPS:g}"


def _key(f) -> tuple:
    return (f.frame, f.status, f.found, f.fitness, f.generations, f.position_mm, f.alpha)


def fidelity_table(duration: float, fps: float) -> list[dict]:
    """Each mode's recording of the same lockstep session, replayed with KEYS changed."""
    from photoservo.cli.main import main as cli
    from photoservo.record.reader import read_recording
    from photoservo.record.replay import load_replay, replay

    rows, results = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for mode, video in (("full", "none"), ("compact", "av1"), ("preview", "av1")):
            path = Path(tmp) / f"{mode}.rrd"
            argv = ["track", "--sim", "--lockstep", "--duration", str(duration), "--seed", "3",
                    "--set", f"sim.camera_fps={fps}", "--record", str(path),
                    "--set", f"recording.mode='{mode}'", "--set", f"recording.video='{video}'"]
            assert cli(argv) == 0
            row = {"mode": mode, "video": video}
            try:
                t0 = time.perf_counter()
                same = replay(load_replay(path), record=False)
                changed = replay(load_replay(path, overrides=KEYS), record=False)
                row["replay_s"] = time.perf_counter() - t0
            except Exception as e:  # noqa: BLE001 - preview: refused, which is the result
                row.update(refused=str(e))
                rows.append(row)
                continue
            rec = read_recording(path)
            recorded = [(e.frame, e.found, e.fitness, e.generations,
                         None if e.position_mm is None else tuple(e.position_mm)) for e in rec.estimates]
            again = [(f.frame, f.found, f.fitness, f.generations, f.position_mm) for f in same.frames]
            results[mode] = changed
            ref = results["full"]
            row.update(frames=len(changed.frames), same_config_reproduces=recorded == again,
                       identical_frames=sum(_key(a) == _key(b) for a, b in zip(changed.frames, ref.frames)),
                       identical_commands=bool(np.array_equal(changed.commands, ref.commands)),
                       mb=path.stat().st_size / 1e6)
            rows.append(row)
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--duration", type=float, default=3.0, help="fidelity session length (s, simulated)")
    ap.add_argument("--fps", type=float, default=10.0, help="fidelity session camera rate")
    ap.add_argument("--skip-fidelity", action="store_true")
    args = ap.parse_args()
    load0 = os.getloadavg()[0]
    print("size and cost per mode (running):")
    sizes = size_table(args.frames, args.repeats)
    fidelity = [] if args.skip_fidelity else fidelity_table(args.duration, args.fps)
    load1 = os.getloadavg()[0]
    print(f"\nRecording 640x480 stereo @ {FPS:.0f} fps, {args.frames} frames x {args.repeats} runs (median); "
          f"{os.cpu_count()} CPUs shared, load average {load0:.1f} -> {load1:.1f}")
    print(f"{'frames':15s} {'mode':8s} {'video':9s} {'MB/min':>7s} {'loop ms':>8s} {'p90':>6s} {'cpu ms':>7s} {'enc ms':>7s}")
    for r in sizes:
        print(f"{r['frames']:15s} {r['mode']:8s} {_video(r['video'], r['video_fps']):9s} {r['mb_per_min']:7.0f} {r['loop_ms']:8.2f} "
              f"{r['loop_p90_ms']:6.2f} {r['cpu_ms']:7.1f} {r['encode_ms']:7.1f}" + (f"  ({r['note']})" if "note" in r else ""))
    if fidelity:
        print(f"\nReplay fidelity: lockstep session {args.duration:g} s at {args.fps:g} fps, replayed with "
              + " ".join(KEYS))
        print(f"{'mode':8s} {'MB':>6s} {'same config = recorded':>23s} {'identical to full frames':>25s}")
        for r in fidelity:
            if "refused" in r:
                print(f"{r['mode']:8s} {'':6s} refused: {r['refused']}")
                continue
            exact = r["identical_frames"] == r["frames"] and r["identical_commands"]
            print(f"{r['mode']:8s} {r['mb']:6.2f} {str(r['same_config_reproduces']):>23s} "
                  f"{r['identical_frames']:>3d}/{r['frames']} frames, commands {'equal' if r['identical_commands'] else 'DIFFER'}"
                  + ("  BIT-EXACT" if exact else ""))
    out = Path(__file__).parent / "out" / "recording.json"
    write_text_atomic(out, json.dumps({"fps": FPS, "size": [640, 480], "frames": args.frames, "repeats": args.repeats,
                                       "load_average": [load0, load1], "keys": KEYS, "sizes": sizes,
                                       "fidelity": fidelity}, indent=1) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
