"""photoservo synth --specimen squid|--photo PHOTO [--other|--estimator-photo PHOTO2] [--seed N]
                  [--distance MM] [--tilt-deg DEG] [--empty] [--distractor] [--effects LIST]
                  [--generator renderer|harbour] [--foam-split] [--many-hued]
                  [--rig RIG.toml] [--config CFG.toml] [--set key=value ...] --out DIR

Renders a synthetic stereo scene: a creature lying on water seen by a rig whose rendering
calibration differs from the written one by the [synthetic] calibration error. The generator is
sim/renderer.py ("renderer", the default) or the independent second generator
sim/harbour.py ("harbour": its own procedural creatures, water, foam, debris and light; with
--foam-split, a foam band cuts the creature in two; --many-hued, a fish in many hues including
the water's).
Writes DIR/left.png, DIR/right.png, DIR/rig.toml (the rig the estimator is told), DIR/truth.json
(ground truth in the estimate-JSON shape, for the photo in DIR/photo.png) and DIR/photo.png
(the photo the estimator should use), each atomically.

Examples:
    photoservo synth --specimen squid --seed 3 --distance 700 --out scene/
    photoservo synth --generator harbour --specimen fish --many-hued --seed 3 --out scene/
    photoservo synth --specimen crab --other --effects all --distractor --out hard/
    photoservo estimate --rig scene/rig.toml --photo scene/photo.png --left scene/left.png --right scene/right.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from photoservo.errors import InputError
from photoservo.fileio import read_image, write_image_atomic, write_text_atomic
from photoservo.cli.options import add_config_options, bounded, seed
from photoservo.config import load_config
from photoservo.vision.photo_model import load_photo_model
from photoservo.vision.rig import dump_rig, load_rig
from photoservo.sim.specimens import SPECIES
from photoservo.sim.scenes import DEFAULT_EFFECTS, EFFECTS, random_scene


def parse_effects(text: str) -> tuple[str, ...]:
    """'waves,glints,noise' | 'all' | 'none' -> a tuple of EFFECTS names."""
    t = text.strip().lower()
    if t == "all":
        return EFFECTS
    if t in ("none", ""):
        return ()
    names = tuple(n.strip() for n in t.split(",") if n.strip())
    for n in names:
        if n not in EFFECTS:
            raise InputError(f"--effects '{n}': unknown effect, choose from {', '.join(EFFECTS)}, all, none")
    return names


def truth_json(truth: dict) -> str:
    """The truth object as JSON text, one key per line (values compact)."""
    return "{\n" + ",\n".join(f" {json.dumps(k)}: {json.dumps(v)}" for k, v in truth.items()) + "\n}\n"


def add_arguments(p: argparse.ArgumentParser) -> None:
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--specimen", choices=SPECIES, help="a procedural creature the project draws")
    src.add_argument("--photo", metavar="PHOTO", help="a photo of the creature to float on the water")
    other = p.add_mutually_exclusive_group()
    other.add_argument("--other", action="store_true",
                       help="with --specimen: the estimator gets a photo of ANOTHER individual")
    other.add_argument("--estimator-photo", metavar="PHOTO2",
                       help="the photo the estimator gets (another individual of the same kind)")
    p.add_argument("--seed", type=seed, default=0, help="scene seed (0..2^32-1, default 0)")
    p.add_argument("--distance", type=bounded(float, 50, 100000, unit="mm"), metavar="MM",
                   help="target depth in the left camera (50..100000 mm; default: random in [synthetic] distance_mm)")
    p.add_argument("--tilt-deg", type=bounded(float, 0, 75, unit="deg"), metavar="DEG",
                   help="angle between target normal and optical axis (0..75 deg; default random)")
    p.add_argument("--empty", action="store_true", help="no creature: empty water (truth found=false)")
    p.add_argument("--distractor", action="store_true", help="add a look-alike elsewhere in view")
    p.add_argument("--effects", default=",".join(DEFAULT_EFFECTS), metavar="LIST",
                   help=f"comma list of {', '.join(EFFECTS)}; or all / none (default: %(default)s)")
    p.add_argument("--generator", choices=("renderer", "harbour"), default="renderer",
                   help="scene generator: sim/renderer.py (default) or the independent sim/harbour.py")
    p.add_argument("--foam-split", action="store_true", help="harbour: a foam band cuts the creature in two")
    p.add_argument("--many-hued", action="store_true", help="harbour, fish: a creature in many hues, the water's among them")
    p.add_argument("--rig", metavar="RIG.toml", help="rig to render and write (default: the synthetic rig)")
    add_config_options(p)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config, args.overrides)
    effects = parse_effects(args.effects)
    if args.other and args.photo:
        raise InputError("--other: only with --specimen; give --estimator-photo PHOTO2 with --photo")
    if args.generator == "harbour":
        if args.photo or args.estimator_photo:
            raise InputError("--generator harbour draws its own creatures: use --specimen, not --photo / --estimator-photo")
        if args.effects != ",".join(DEFAULT_EFFECTS):
            raise InputError("--effects: only with --generator renderer (harbour scenes carry their own light, waves and foam)")
        if args.many_hued and args.specimen != "fish":
            raise InputError("--many-hued: only with --specimen fish")
    elif args.foam_split or args.many_hued:
        raise InputError("--foam-split / --many-hued: only with --generator harbour")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a folder")
    rig = load_rig(args.rig) if args.rig else None
    photo = est = None
    if args.photo:
        load_photo_model(args.photo, cfg.photo_model)  # fail early, naming the file
        photo = read_image(args.photo, "photo")
    if args.estimator_photo:
        load_photo_model(args.estimator_photo, cfg.photo_model)
        est = read_image(args.estimator_photo, "photo")
    if args.generator == "harbour":
        from photoservo.sim import harbour

        sc = harbour.random_scene(args.seed, cfg.synthetic, cfg.photo_model, kind=args.specimen,
                                  other_photo=bool(args.other), empty=args.empty, distractor=args.distractor,
                                  foam_split=args.foam_split, many_hued=args.many_hued,
                                  distance_mm=args.distance, tilt_deg=args.tilt_deg, rig=rig)
    else:
        sc = random_scene(args.seed, cfg.synthetic, cfg.photo_model, kind=args.specimen or "squid",
                          other_photo=bool(args.other), effects=effects, empty=args.empty,
                          distractor=args.distractor, distance_mm=args.distance, tilt_deg=args.tilt_deg,
                          photo=photo, estimator_photo=est, rig=rig)
    truth = dict(sc.truth)
    truth["photo"] = "photo.png"
    write_image_atomic(out / "left.png", sc.left)
    write_image_atomic(out / "right.png", sc.right)
    write_image_atomic(out / "photo.png", sc.photo)
    write_text_atomic(out / "rig.toml", dump_rig(sc.rig))
    write_text_atomic(out / "truth.json", truth_json(truth))
    if truth["found"]:
        x, y, z = truth["position_mm"]
        print(f"wrote {out}/: left.png right.png rig.toml truth.json photo.png — target at "
              f"({x:.0f}, {y:.0f}, {z:.0f}) mm, tilt {truth['tilt_deg']:.1f} deg, "
              f"size {truth['size_mm'][0]:.0f} x {truth['size_mm'][1]:.0f} mm")
    else:
        print(f"wrote {out}/: left.png right.png rig.toml truth.json photo.png — no target (empty water)")
    return 0
