"""photoservo model --photo PHOTO [--roi X,Y,W,H] [--preview OUT.png] [--config CFG.toml] [--set key=value ...]

Builds the photo-model (method steps 1-2, vision/photo_model.py) of one photo and prints what it
found: target size, model origin, inner/outer point counts, target hues. With --preview, writes a
PNG of the inner points (in their own hue) and outer points (grey) over the photo.

Examples:
    photoservo model --photo examples/photos/squid.png --preview squid_model.png
    photoservo model --photo harbour.jpg --roi 120,80,300,200 --set photo_model.interval_px=6
"""

from __future__ import annotations

import argparse

import numpy as np

from photoservo.fileio import read_image, write_image_atomic
from photoservo.cli.options import add_config_options, output_image
from photoservo.config import load_config
from photoservo.vision.photo_model import draw_photo_model, load_photo_model, parse_roi


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--photo", required=True, metavar="PHOTO", help="photo of the kind of creature")
    p.add_argument("--roi", metavar="X,Y,W,H", help="cluttered photo: GrabCut inside this rectangle (px)")
    p.add_argument("--preview", metavar="OUT.png", type=output_image,
                   help="write the model drawn over the photo (.png or .jpg)")
    add_config_options(p)


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config, args.overrides)
    roi = parse_roi(args.roi) if args.roi else None
    model = load_photo_model(args.photo, cfg.photo_model, roi)
    if args.preview:
        write_image_atomic(args.preview, draw_photo_model(read_image(args.photo, "photo"), model))
    hues = np.flatnonzero(model.target_hues)
    print(f"{args.photo}: target {model.size_px[0]:.0f} x {model.size_px[1]:.0f} px, origin "
          f"({model.origin_px[0]:.1f}, {model.origin_px[1]:.1f}) px, {len(model.inner_uv)} inner + "
          f"{len(model.outer_uv)} outer points, {hues.size} target hues")
    if args.preview:
        print(f"preview: {args.preview}")
    return 0
