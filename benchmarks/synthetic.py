"""Synthetic-scene and photo-model costs (issue 2 items 2 and 7): how long the tools the other
benchmarks and the simulator lean on take, and how faithful the rendering is.

Rows:
  * photo-model: `build_photo_model` on each shipped specimen photo (ms, inner/outer points).
  * render: one stereo frame (640x480 x 2) of a squid scene by `StereoRenderer.render` (rays
    cached, as the simulator renders video) and by `render_stereo` (rays computed per call),
    with the default effects (waves, glints, noise) and with every effect.
  * random_scene: a whole generated scene (specimens drawn, photo-models, camera placement,
    render) with default effects, as the accuracy benchmark calls it.
  * geometry: over seeded scenes, the distance (px) between green markers drawn on a photo at
    known model points and the projection of those points with the ground-truth pose
    (`project_points` with the rendering rig), left and right — the renderer's geometric error.
  * other photo: scale and shift between the ground truth's area/centroid matching of the two
    individuals and their best-overlap (IoU) alignment, per species.

The machine has 2 cores shared with other jobs: the load average is stored; wall times are
pessimistic, the CPU column is the steadier one. Medians of repeated runs.

Prints a table and writes benchmarks/out/synthetic.json.
Run: python benchmarks/synthetic.py [--repeats 5]
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
from photoservo.vision.photo_model import build_photo_model
from photoservo.vision.rig import project_points
from photoservo.sim.specimens import SPECIES, specimen
from photoservo.sim.renderer import StereoRenderer, render_stereo
from photoservo.sim.scenes import DEFAULT_EFFECTS, EFFECTS, random_scene

MARKS_UV = np.array([[0.0, 0.0], [-45.0, -18.0], [45.0, -18.0], [45.0, 18.0], [-45.0, 18.0]])


def timed(fn, repeats: int) -> dict:
    fn()
    walls, c0 = [], time.process_time()
    for _ in range(repeats):
        w0 = time.perf_counter()
        fn()
        walls.append(time.perf_counter() - w0)
    return {"median_ms": 1e3 * float(np.median(walls)), "cpu_ms": 1e3 * (time.process_time() - c0) / repeats,
            "repeats": repeats}


def marked_photo() -> np.ndarray:
    photo = np.full((121, 201, 3), 250, np.uint8)
    cv2.ellipse(photo, (100, 60), (80, 40), 0, 0, 360, (30, 30, 220), -1)
    for du, dv in MARKS_UV:
        cv2.circle(photo, (int(100 + du), int(60 + dv)), 8 if du else 12, (40, 200, 40), -1)
    return photo


def marker_errors(sc) -> list[float]:
    t = sc.truth
    R, X, a = np.array(t["rotation"]), np.array(t["position_mm"]), t["alpha_px_per_mm"]
    Xm = np.column_stack([MARKS_UV / a, np.zeros(len(MARKS_UV))]) @ R.T + X
    rt = sc.rig_true
    errs = []
    for img, uv in ((sc.left, project_points(Xm, rt.left)), (sc.right, project_points(Xm @ rt.R.T + rt.T, rt.right))):
        hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
        m = ((np.abs(hsv[..., 0].astype(int) - 60) < 12) & (hsv[..., 1] > 100)).astype(np.uint8)
        _, _, stats, cents = cv2.connectedComponentsWithStats(m)
        blobs = cents[1:][stats[1:, cv2.CC_STAT_AREA] >= 4]
        errs += list(np.linalg.norm(blobs[:, None] - uv[None], axis=-1).min(axis=0))
    return errs


def iou_alignment(kind: str, params) -> dict:
    """Best-overlap similarity (scale, shift) of the other individual's mask onto the reference
    one, relative to the area/centroid matching that random_scene's ground truth uses."""
    A = build_photo_model(specimen(kind), params)
    B = build_photo_model(specimen(kind, 0, True), params)
    def cen(m):
        return np.array(np.nonzero(m.mask)[::-1], float).mean(axis=1)

    cA, cB = cen(A), cen(B)
    s0 = float(np.sqrt(np.count_nonzero(A.mask) / np.count_nonzero(B.mask)))

    def iou(s, dx, dy):
        M = np.array([[s, 0, cA[0] - cB[0] * s + dx], [0, s, cA[1] - cB[1] * s + dy]])
        w = cv2.warpAffine(B.mask, M, (A.mask.shape[1], A.mask.shape[0])) > 127
        a = A.mask > 0
        return float((a & w).sum() / (a | w).sum())

    x, best = [s0, 0.0, 0.0], iou(s0, 0, 0)
    start = best
    steps = [0.04 * s0, 4.0, 4.0]
    while steps[1] >= 0.25:
        improved = False
        for k in range(3):
            for sg in (-1, 1):
                y = list(x)
                y[k] += sg * steps[k]
                v = iou(*y)
                if v > best:
                    x, best, improved = y, v, True
        if not improved:
            steps = [s / 2 for s in steps]
    return {"iou_area_centroid": start, "iou_best": best, "scale_ratio": x[0] / s0,
            "shift_px": [x[1], x[2]], "reference_length_px": A.size_px[0]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--scenes", type=int, default=8, help="seeded scenes for the geometry row")
    args = ap.parse_args()
    cfg = load_config()
    out: dict = {"load_average": os.getloadavg(), "repeats": args.repeats}

    rows = []
    out["photo_model"] = {}
    for kind in SPECIES:
        for other in (False, True):
            photo = specimen(kind, 0, other)
            r = timed(lambda p=photo: build_photo_model(p, cfg.photo_model), args.repeats)
            m = build_photo_model(photo, cfg.photo_model)
            r.update(inner=len(m.inner_uv), outer=len(m.outer_uv))
            name = f"{kind}{'_other' if other else ''}"
            out["photo_model"][name] = r
            rows.append((f"photo-model {name}", f"{r['median_ms']:.1f}", f"{r['cpu_ms']:.1f}",
                         f"{r['inner']} inner + {r['outer']} outer"))

    out["render"] = {}
    for label, fx in (("default effects", DEFAULT_EFFECTS), ("all effects", EFFECTS)):
        sc = random_scene(3, cfg.synthetic, cfg.photo_model, effects=fx, distractor=True)
        ren = StereoRenderer(sc.rig_true)
        rng = np.random.default_rng(0)
        r1 = timed(lambda ren=ren, sc=sc, rng=rng: ren.render(sc.scene, sc.T_world_left, 0.1, rng), args.repeats)
        r2 = timed(lambda sc=sc, rng=rng: render_stereo(sc.scene, sc.rig_true, sc.T_world_left, 0.1, rng),
                   args.repeats)
        out["render"][label] = {"StereoRenderer.render": r1, "render_stereo": r2}
        rows.append((f"render stereo 640x480, rays cached, {label}", f"{r1['median_ms']:.0f}", f"{r1['cpu_ms']:.0f}", ""))
        rows.append((f"render_stereo 640x480 (rays per call), {label}", f"{r2['median_ms']:.0f}", f"{r2['cpu_ms']:.0f}", ""))

    k = iter(range(1000))
    r = timed(lambda: random_scene(next(k), cfg.synthetic, cfg.photo_model), args.repeats)
    out["random_scene"] = r
    rows.append(("random_scene (default effects)", f"{r['median_ms']:.0f}", f"{r['cpu_ms']:.0f}", ""))

    errs = []
    for seed in range(args.scenes):
        sc = random_scene(seed, cfg.synthetic, cfg.photo_model, photo=marked_photo(), effects=(),
                          distance_mm=float(300 + 150 * (seed % 6)))
        errs += marker_errors(sc)
    errs = np.array(errs)
    out["geometry_px"] = {"median": float(np.median(errs)), "p90": float(np.percentile(errs, 90)),
                          "max": float(errs.max()), "n": int(errs.size)}
    rows.append(("geometry: marker vs truth projection (px)", "", "",
                 f"median {np.median(errs):.3f}, p90 {np.percentile(errs, 90):.3f}, max {errs.max():.3f} (n={errs.size})"))

    out["other_photo_alignment"] = {}
    for kind in SPECIES:
        a = iou_alignment(kind, cfg.photo_model)
        out["other_photo_alignment"][kind] = a
        rows.append((f"other photo {kind}: IoU-best vs truth matching", "", "",
                     (f"scale x{a['scale_ratio']:.3f}, shift ({a['shift_px'][0]:.1f}, {a['shift_px'][1]:.1f}) px, "
                      f"IoU {a['iou_area_centroid']:.3f} -> {a['iou_best']:.3f}")))

    w = max(len(r[0]) for r in rows)
    print(f"load average {out['load_average'][0]:.2f} (2 cores shared: wall times pessimistic)")
    print(f"{'what'.ljust(w)}  {'wall ms':>8}  {'cpu ms':>7}  notes")
    for name, wall, cpu, note in rows:
        print(f"{name.ljust(w)}  {wall:>8}  {cpu:>7}  {note}")
    path = Path(__file__).parent / "out" / "synthetic.json"
    write_text_atomic(path, json.dumps(out, indent=1) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
