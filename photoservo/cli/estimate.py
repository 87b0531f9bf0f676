"""photoservo estimate --rig RIG.toml --photo PHOTO --left L.png --right R.png [--roi X,Y,W,H]
                    [--config CFG.toml] [--set key=value ...] [--seed N] [--json] [--all]
                    [--preview OUT.png]

Finds the photo's creature in one stereo pair and prints its 6-DOF pose (model in the left
camera frame) and real size. With --json, exactly the estimate object of DESIGN.md on stdout.
Exit status: 0 found, 1 not found, 2 bad input. Same seed and inputs, same pose (only
"seconds" differs from run to run).

Examples:
    photoservo estimate --rig examples/scene/rig.toml --photo examples/scene/photo.png \\
        --left examples/scene/left.png --right examples/scene/right.png --preview est.png
    photoservo estimate --rig scene/rig.toml --photo scene/photo.png --left scene/left.png \\
        --right scene/right.png --json --all --seed 7
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np

from photoservo.cli.output import dumps_strict
from photoservo.cli.options import add_config_options, add_stereo_inputs, load_stereo_inputs, output_image, seed
from photoservo.config import load_config
from photoservo.fileio import write_image_atomic
from photoservo.geometry import heading_tilt_from_rotation
from photoservo.vision.estimator import Estimate, estimate
from photoservo.vision.photo_model import PhotoModel
from photoservo.vision.rig import Rig, project_points


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_stereo_inputs(p)
    add_config_options(p)
    p.add_argument("--seed", type=seed, default=0, help="random seed of the GA (0..2^32-1, default 0)")
    p.add_argument("--json", action="store_true", help="print only the estimate JSON object (strict JSON)")
    p.add_argument("--all", action="store_true", help="also list every candidate (key 'candidates' with --json)")
    p.add_argument("--preview", metavar="OUT.png", type=output_image,
                   help="write both images side by side with the estimated model's outline drawn on them")


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config, args.overrides)
    rig, model, left, right = load_stereo_inputs(args, cfg)
    est = estimate(model, left, right, rig, cfg.ga, cfg.estimator, cfg.fitness, seed=args.seed)
    if args.preview:
        write_image_atomic(args.preview, draw_estimate(left, right, model, rig, est))
    if args.json:
        print(dumps_strict(est.to_json(with_candidates=args.all)))
    else:
        print(describe(est, args.all))
    return 0 if est.found else 1


def describe(est: Estimate, with_candidates: bool = False) -> str:
    """Human-readable summary of an estimate."""
    lines = []
    if est.found:
        psi, tx, ty = heading_tilt_from_rotation(est.rotation)
        x, y, z = est.position_mm
        lines += [
            f"found        yes (fitness {est.fitness:.3f}, confidence {est.confidence:.2f})",
            f"position     x {x:.1f}  y {y:.1f}  z {z:.1f} mm (left camera frame)",
            f"heading      {np.degrees(psi):.1f} deg   tilt {np.degrees(np.hypot(tx, ty)):.1f} deg",
            f"size         {est.size_mm[0]:.1f} x {est.size_mm[1]:.1f} mm   (alpha {est.alpha_px_per_mm:.4f} px/mm)",
        ]
    else:
        f = "-" if est.fitness is None else f"{est.fitness:.3f}"
        lines.append(f"found        no (best fitness {f}, confidence {est.confidence:.2f})")
    lines.append(f"search       {est.generations} generations, {est.evaluations} evaluations, {est.seconds:.2f} s")
    if with_candidates:
        for i, c in enumerate(est.candidates):
            x, y, z = c["position_mm"]
            lines.append(f"candidate {i}  fitness {c['fitness']:.3f}  at ({x:.0f}, {y:.0f}, {z:.0f}) mm  "
                         f"size {c['size_mm'][0]:.0f} x {c['size_mm'][1]:.0f} mm  [{c['source']}]"
                         f"{'' if c['found'] else '  below threshold'}")
    return "\n".join(lines)


def model_outline_mm(model: PhotoModel, alpha: float) -> list[np.ndarray]:
    """The photo-model's outline (the target mask's outer contours) as model-frame points
    (method step 2: pixel (u, v) from the origin -> (u/alpha, v/alpha, 0) mm), one (n, 3) array
    per contour."""
    contours, _ = cv2.findContours(model.mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    out = []
    for c in contours:
        uv = c.reshape(-1, 2).astype(np.float64) - np.asarray(model.origin_px)
        out.append(np.column_stack([uv / alpha, np.zeros(len(uv))]))
    return out


def draw_estimate(left: np.ndarray, right: np.ndarray, model: PhotoModel, rig: Rig, est: Estimate) -> np.ndarray:
    """Both images side by side with the estimated model's outline projected on them (a thin
    line in the target's own hue over a dark one, so the creature stays visible). Not found:
    the best candidate's outline in grey, labelled. BGR uint8."""
    imgs = [left.copy(), right.copy()]
    cand = None
    if est.found:
        cand = (est.rotation, est.position_mm, est.alpha_px_per_mm)
    elif est.candidates:
        c = est.candidates[0]
        cand = (np.array(c["rotation"]), np.array(c["position_mm"]), c["alpha_px_per_mm"])
    if cand is not None:
        R, t, alpha = np.asarray(cand[0], float), np.asarray(cand[1], float), float(cand[2])
        hue = int(np.median(model.inner_hue)) if len(model.inner_hue) else 0
        colour = cv2.cvtColor(np.uint8([[[hue, 255, 255]]]), cv2.COLOR_HSV2BGR)[0, 0]
        colour = tuple(int(v) for v in colour) if est.found else (190, 190, 190)
        for X in model_outline_mm(model, alpha):
            X_left = X @ R.T + t
            X_right = X_left @ rig.R.T + rig.T
            for img, cam, Xc in ((imgs[0], rig.left, X_left), (imgs[1], rig.right, X_right)):
                uv = project_points(Xc, cam)
                uv = uv[np.all(np.isfinite(uv), axis=1)]
                if len(uv) < 2:
                    continue
                pts = np.round(uv).astype(np.int32).reshape(-1, 1, 2)
                cv2.polylines(img, [pts], True, (0, 0, 0), 3, cv2.LINE_AA)
                cv2.polylines(img, [pts], True, colour, 1, cv2.LINE_AA)
    label = (f"found  fitness {est.fitness:.3f}  z {est.position_mm[2]:.0f} mm  "
             f"size {est.size_mm[0]:.0f}x{est.size_mm[1]:.0f} mm" if est.found else "not found (best candidate in grey)")
    for img, name in zip(imgs, ("left", "right")):
        cv2.putText(img, f"{name}: {label}", (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(img, f"{name}: {label}", (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    h = max(i.shape[0] for i in imgs)
    imgs = [cv2.copyMakeBorder(i, 0, h - i.shape[0], 0, 0, cv2.BORDER_CONSTANT) for i in imgs]
    return np.hstack(imgs)
