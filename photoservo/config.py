"""Typed, validated configuration: `configs/default.toml` is the single source of defaults (each
key documented there); a user file and `--set section.key=value` overrides are merged on top and
go through the same validation. An unknown key or a wrong type is an InputError naming the key.

Each section is a frozen dataclass owned by the module that uses it (vision sections live in
vision/, so vision never imports servo); `Config` only gathers them.
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from photoservo.errors import InputError
from photoservo.sim.bridge import EmulatorParams
from photoservo.robot.link import LinkParams
from photoservo.tomlconf import build_dataclass, configs_dir, read_toml
from photoservo.vision.estimator import EstimatorParams
from photoservo.vision.ga import GAParams
from photoservo.servo.control import ServoParams
from photoservo.servo.motion import MotionParams
from photoservo.record.recorder import RecordingParams
from photoservo.sim.world import SimParams
from photoservo.vision.fitness import FitnessParams
from photoservo.vision.photo_model import PhotoModelParams
from photoservo.vision.source_config import CamerasParams
from photoservo.sim.scenes import SynthParams
from photoservo.vision.tracker_params import TrackerParams


@dataclass(frozen=True)
class Config:
    """The effective configuration: one field per section of configs/default.toml."""

    photo_model: PhotoModelParams
    fitness: FitnessParams
    ga: GAParams
    estimator: EstimatorParams
    servo: ServoParams
    tracker: TrackerParams
    sim: SimParams
    synthetic: SynthParams
    link: LinkParams
    emulator: EmulatorParams
    motion: MotionParams
    cameras: CamerasParams
    recording: RecordingParams


def _merge(base: dict, top: dict, src: str, prefix: str = "") -> dict:
    """Deep-merge `top` (read from file `src`) into a copy of `base`; a key absent from `base`
    is unknown."""
    out = dict(base)
    for k, v in top.items():
        key = f"{prefix}{k}"
        if k not in base:
            raise InputError(f"{src}: unknown key '{key}'")
        if isinstance(base[k], dict):
            if not isinstance(v, dict):
                raise InputError(f"{src}: '{key}' must be a table")
            out[k] = _merge(base[k], v, src, f"{key}.")
        else:
            out[k] = v
    return out


def parse_override(text: str) -> tuple[list[str], Any]:
    """'section.key=value' -> (['section', 'key'], value); value parsed as a TOML value, or
    taken as a plain string when it is not one (so `--set sim.target=squid` works)."""
    if "=" not in text:
        raise InputError(f"--set '{text}': expected section.key=value")
    key, raw = text.split("=", 1)
    path = [p.strip() for p in key.strip().split(".")]
    if not all(path):
        raise InputError(f"--set '{text}': empty key")
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return path, value


def load_config_dict(path: str | os.PathLike | None = None, overrides: Sequence[str] = (),
                     recorded: tuple[str, dict] | None = None) -> dict:
    """Defaults <- `recorded` <- user file <- overrides, as a raw dict (not yet validated against
    types). `recorded` = (where it comes from, table): the effective config stored in a recording
    (replay, `track --world-from`); keys it lacks keep their defaults."""
    doc = read_toml(configs_dir() / "default.toml")
    if recorded is not None:
        doc = _merge(doc, recorded[1], recorded[0])
    if path is not None:
        doc = _merge(doc, read_toml(Path(path)), str(path))
    for text in overrides:
        keys, value = parse_override(text)
        node = doc
        for i, k in enumerate(keys[:-1]):
            if not isinstance(node.get(k), dict):
                raise InputError(f"--set '{text}': unknown key '{'.'.join(keys[: i + 1])}'")
            node = node[k]
        if keys[-1] not in node or isinstance(node[keys[-1]], dict):
            raise InputError(f"--set '{text}': unknown key '{'.'.join(keys)}'")
        node[keys[-1]] = value
    return doc


def load_config(path: str | os.PathLike | None = None, overrides: Sequence[str] = (),
                recorded: tuple[str, dict] | None = None) -> Config:
    """The effective, validated configuration (`recorded`: see load_config_dict): types by the
    sections' dataclasses, ranges by configs/bounds.toml, then each section's validate()."""
    doc = load_config_dict(path, overrides, recorded)
    check_bounds(doc, read_toml(configs_dir() / "bounds.toml"))
    return build_dataclass(Config, doc, "")


def check_bounds(doc: dict, bounds: dict) -> None:
    """Every number in `doc` (a config as raw TOML tables) finite and within its key's
    [lowest, highest] in `bounds` (configs/bounds.toml; a list key's bound holds for each
    element). InputError naming the key, the value and the bound. Non-numbers are left to the
    type checks of build_dataclass."""
    nan_ok = set(bounds.get("nan_means_unknown", ()))
    for section, table in doc.items():
        if not isinstance(table, dict):
            continue
        for key, value in table.items():
            name = f"{section}.{key}"
            values = value if isinstance(value, list) else [value]
            nums = [v for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)]
            if not nums:
                continue
            lo, hi = bounds.get(section, {}).get(key, (None, None))
            for v in nums:
                if isinstance(v, float) and math.isnan(v) and name in nan_ok:
                    continue
                if not math.isfinite(v):
                    raise InputError(f"config key '{name}' = {v}: must be a finite number"
                                     + (f" within {lo:g}..{hi:g}" if lo is not None else ""))
                if lo is not None and not lo <= v <= hi:
                    raise InputError(f"config key '{name}' = {v if isinstance(v, int) else f'{v:g}'}: "
                                     f"must be within {lo:g}..{hi:g}")


