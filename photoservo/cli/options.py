"""Options and argument checks shared by several verbs (verbs never import each other).

argparse `type=` functions here reject a bad value while the command line is parsed, before
any work starts: one line naming the flag and the allowed range, exit status 2.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
from pathlib import Path

from photoservo.errors import InputError

log = logging.getLogger(__name__)

SEED_MAX = 2**32 - 1  # numpy's SeedSequence takes any non-negative int; 32 bits is plenty to type


# ----------------------------------------------------------------------------- argparse types


def _number(text: str, kind: type) -> float | int:
    try:
        v = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not {'an integer' if kind is int else 'a number'}") from None
    if kind is float and not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return v


def _fmt(v: float | int | None) -> str:
    return str(v) if isinstance(v, int) else f"{v:g}"


def bounded(kind: type, lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
            unit: str = ""):
    """An argparse type: an int or finite float within [lo, hi] (lo excluded when lo_open)."""
    def parse(text: str) -> float | int:
        v = _number(text, kind)
        low_bad = lo is not None and (v <= lo if lo_open else v < lo)
        if low_bad or (hi is not None and v > hi):
            a, b = _fmt(lo), _fmt(hi)
            if lo is not None and hi is not None:
                rng = f"within {a}..{b}" if not lo_open else f"> {a} and <= {b}"
            elif lo is not None:
                rng = f"> {a}" if lo_open else f">= {a}"
            else:
                rng = f"<= {b}"
            raise argparse.ArgumentTypeError(f"{text} must be {rng}{(' ' + unit) if unit else ''}")
        return v

    parse.__name__ = kind.__name__  # argparse names the type in its messages
    return parse


seed = bounded(int, 0, SEED_MAX)
finite = bounded(float)
positive = bounded(float, 0.0, lo_open=True)
rt_priority = bounded(int, 1, 99)


def output_image(text: str) -> str:
    """An image file to write: a name with an image extension OpenCV can encode, not a folder."""
    p = Path(text)
    if p.is_dir() or text.endswith(os.sep):
        raise argparse.ArgumentTypeError(f"{text}: is a folder; give an image file name such as {p / 'preview.png'}")
    ext = p.suffix.lower()
    if ext not in (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp"):
        raise argparse.ArgumentTypeError(f"{text}: unknown image type '{ext or '(none)'}'; use .png or .jpg")
    return text


# ----------------------------------------------------------------------------- shared groups


def add_stereo_inputs(p: argparse.ArgumentParser) -> None:
    """--rig, --photo, --roi, --left, --right: one photo and one stereo frame (estimate, scan)."""
    p.add_argument("--rig", required=True, metavar="RIG.toml", help="calibrated stereo rig (DESIGN.md format)")
    p.add_argument("--photo", required=True, metavar="PHOTO", help="one photo of the kind of creature sought")
    p.add_argument("--roi", metavar="X,Y,W,H", help="region of the photo holding the creature (px), for cluttered photos")
    p.add_argument("--left", required=True, metavar="L.png", help="left camera image")
    p.add_argument("--right", required=True, metavar="R.png", help="right camera image")


def load_stereo_inputs(args: argparse.Namespace, cfg):
    """(rig, photo-model, left BGR, right BGR) from the `add_stereo_inputs` options; InputError
    naming the file when one is unreadable or an image's size is not the rig's."""
    from photoservo.fileio import read_image
    from photoservo.vision.photo_model import load_photo_model, parse_roi
    from photoservo.vision.rig import load_rig

    rig = load_rig(args.rig)
    warn_baseline_sign(args.rig, rig)
    roi = parse_roi(args.roi) if args.roi else None
    model = load_photo_model(args.photo, cfg.photo_model, roi)
    left = read_image(args.left, "left image")
    right = read_image(args.right, "right image")
    for name, img, cam in (("left", left, rig.left), ("right", right, rig.right)):
        if (img.shape[1], img.shape[0]) != tuple(cam.size):
            raise InputError(f"{getattr(args, name)}: image is {img.shape[1]}x{img.shape[0]} px but the rig's "
                             f"[{name}] size is {cam.size[0]}x{cam.size[1]}")
    return rig, model, left, right



def warn_baseline_sign(path: str, rig) -> None:
    """A rig whose right camera sits to the LEFT of the left one (T x > 0 in X_right = R X_left
    + T) is almost always a swapped sign or swapped cameras; the search then finds nothing."""
    if rig.T[0] > 0:
        log.warning(f"{path}: [stereo] T x = {rig.T[0]:+.1f} mm puts the right camera {rig.T[0]:.0f} mm LEFT of "
                    "the left one (X_right = R X_left + T, so T x is minus the baseline); if it is not, the "
                    "sign of T or the left/right images are swapped")




def add_config_options(p: argparse.ArgumentParser) -> None:
    """--config and --set, shared by every verb that reads the configuration."""
    p.add_argument("--config", metavar="CFG.toml", help="config file with the keys to change (see configs/default.toml)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override one key, e.g. --set ga.population=60 (repeatable; ranges in configs/bounds.toml)")


def add_recording_options(p: argparse.ArgumentParser, verb: str) -> None:
    """--record / --no-record."""
    rec = p.add_mutually_exclusive_group()
    rec.add_argument("--record", metavar="OUT.rrd", help=f"recording path (default logs/<UTC time>_{verb}.rrd)")
    rec.add_argument("--no-record", action="store_true", help="do not record")


def check_display(flag: str = "--view") -> None:
    """A viewer window needs a display: one line instead of a flood of the viewer's errors."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise InputError(f"{flag}: no display here (DISPLAY and WAYLAND_DISPLAY are unset); stream to a viewer "
                         "elsewhere with --connect URL, or open the recording later with `rerun FILE.rrd`")


def realtime_or_input_error(priority: int) -> None:
    """`--rt-priority N`: SCHED_FIFO for this process, or a one-line InputError."""
    from photoservo.robot.clock import set_realtime

    try:
        set_realtime(priority)
    except ValueError as e:
        raise InputError(f"--rt-priority {priority}: {e}") from None
    except (OSError, AttributeError) as e:
        raise InputError(f"--rt-priority {priority}: not permitted here ({e}); run without it, "
                         "or grant CAP_SYS_NICE / an rtprio limit") from None


def open_link(port: str, link_params, joint_names: tuple[str, ...] | None = None):
    """An open `robot.link.Link` to the bridge at `port`. A port path that does not exist is bad
    input (InputError, exit 2); a port that exists but whose bridge does not answer is a
    hardware failure (LinkError, exit 3)."""
    from photoservo.robot.link import Link, LinkError

    if "://" not in port and not Path(port).exists():
        raise InputError(f"--port {port}: cannot open: no such device; `photoservo find-port` lists the serial ports")
    link = Link(port, link_params, joint_names)
    try:
        link.open()
    except LinkError as e:
        raise LinkError(f"--port {port}: {e}") from None
    return link


__all__ = ["add_config_options", "add_recording_options", "bounded",
           "check_display", "finite", "open_link", "output_image", "positive", "realtime_or_input_error",
           "rt_priority", "seed"]
