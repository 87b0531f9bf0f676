"""photoservo estimate --rig RIG.toml --photo PHOTO --left L.png --right R.png [--roi X,Y,W,H]
                    [--config CFG.toml] [--set key=value ...] [--seed N] [--json] [--all]
                    [--preview OUT.png]

Finds the photo's creature in one stereo pair and prints its 6-DOF pose (model in the left
camera frame) and real size. With --json, exactly the estimate object of DESIGN.md on stdout.
Exit status: 0 found, 1 not found, 2 bad input. Same seed and inputs, same pose (only
"seconds" differs from run to run).

Example:
    photoservo estimate --rig scene/rig.toml --photo examples/photos/squid.png \\
        --left scene/left.png --right scene/right.png --json --preview est.png
"""

from __future__ import annotations

import argparse
import json

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.fileio import read_image, write_image_atomic
from photoservo.cli.options import add_config_options
from photoservo.config import Config, load_config
from photoservo.vision.estimator import Estimate, estimate
from photoservo.vision.fitness import project_model
from photoservo.vision.photo_model import PhotoModel, load_photo_model, parse_roi
from photoservo.geometry import heading_tilt_from_rotation
from photoservo.vision.rig import Rig, load_rig


def add_stereo_inputs(p: argparse.ArgumentParser) -> None:
    """--rig, --photo, --roi, --left, --right: one photo and one stereo frame (estimate, scan)."""
    p.add_argument("--rig", required=True, metavar="RIG.toml", help="calibrated stereo rig (DESIGN.md format)")
    p.add_argument("--photo", required=True, metavar="PHOTO", help="one photo of the kind of creature sought")
    p.add_argument("--roi", metavar="X,Y,W,H", help="region of the photo holding the creature (px), for cluttered photos")
    p.add_argument("--left", required=True, metavar="L.png", help="left camera image")
    p.add_argument("--right", required=True, metavar="R.png", help="right camera image")


def load_stereo_inputs(args: argparse.Namespace, cfg: Config) -> tuple[Rig, PhotoModel, np.ndarray, np.ndarray]:
    """(rig, photo-model, left BGR, right BGR) from the `add_stereo_inputs` options; InputError
    naming the file when one is unreadable or an image's size is not the rig's."""
    rig = load_rig(args.rig)
    roi = parse_roi(args.roi) if args.roi else None
    model = load_photo_model(args.photo, cfg.photo_model, roi)
    left = read_image(args.left, "left image")
    right = read_image(args.right, "right image")
    for name, img, cam in (("left", left, rig.left), ("right", right, rig.right)):
        if (img.shape[1], img.shape[0]) != tuple(cam.size):
            raise InputError(f"{getattr(args, name)}: image is {img.shape[1]}x{img.shape[0]} px but the rig's "
                             f"[{name}] size is {cam.size[0]}x{cam.size[1]}")
    return rig, model, left, right


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_stereo_inputs(p)
    add_config_options(p)
    p.add_argument("--seed", type=int, default=0, help="random seed of the GA (default 0)")
    p.add_argument("--json", action="store_true", help="print only the estimate JSON object")
    p.add_argument("--all", action="store_true", help="also list every candidate (key 'candidates' with --json)")
    p.add_argument("--preview", metavar="OUT.png", help="write both images with the estimated model drawn on them")


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config, args.overrides)
    rig, model, left, right = load_stereo_inputs(args, cfg)
    est = estimate(model, left, right, rig, cfg.ga, cfg.estimator, cfg.fitness, seed=args.seed)
    if args.preview:
        write_image_atomic(args.preview, draw_estimate(left, right, model, rig, est))
    if args.json:
        print(json.dumps(est.to_json(with_candidates=args.all)))
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


def draw_estimate(left: np.ndarray, right: np.ndarray, model: PhotoModel, rig: Rig, est: Estimate) -> np.ndarray:
    """Both images side by side with the estimated model's inner points (in their own hue, ringed
    white) and outer points (dark) projected on them. Not found: the best candidate in grey,
    labelled. BGR uint8."""
    imgs = [left.copy(), right.copy()]
    cand = None
    if est.found:
        cand = (est.rotation, est.position_mm, est.alpha_px_per_mm)
    elif est.candidates:
        c = est.candidates[0]
        cand = (np.array(c["rotation"]), np.array(c["position_mm"]), c["alpha_px_per_mm"])
    if cand is not None:
        p = project_model(cand[0], cand[1], cand[2], model, rig)
        hsv = np.stack([model.inner_hue, np.full_like(model.inner_hue, 255), np.full_like(model.inner_hue, 230)], -1)
        cols = cv2.cvtColor(hsv[None].astype(np.uint8), cv2.COLOR_HSV2BGR)[0]
        for img, inner, outer in ((imgs[0], p.inner_left[0], p.outer_left[0]), (imgs[1], p.inner_right[0], p.outer_right[0])):
            for q in outer:
                if np.all(np.isfinite(q)):
                    cv2.circle(img, (round(q[0]), round(q[1])), 1, (40, 40, 40), -1)
            for q, c in zip(inner, cols):
                if np.all(np.isfinite(q)):
                    colour = tuple(int(v) for v in c) if est.found else (160, 160, 160)
                    cv2.circle(img, (round(q[0]), round(q[1])), 2, colour, -1)
                    cv2.circle(img, (round(q[0]), round(q[1])), 2, (255, 255, 255), 1)
    label = (f"found  fitness {est.fitness:.3f}  z {est.position_mm[2]:.0f} mm  "
             f"size {est.size_mm[0]:.0f}x{est.size_mm[1]:.0f} mm" if est.found else "not found (best candidate in grey)")
    for img, name in zip(imgs, ("left", "right")):
        cv2.putText(img, f"{name}: {label}", (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(img, f"{name}: {label}", (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    h = max(i.shape[0] for i in imgs)
    imgs = [cv2.copyMakeBorder(i, 0, h - i.shape[0], 0, 0, cv2.BORDER_CONSTANT) for i in imgs]
    return np.hstack(imgs)
