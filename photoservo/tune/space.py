"""The search space of `photoservo tune` (issue 14): which config keys a study varies, over which
range or choices, checked against the configuration before any trial runs.

Two spellings, one meaning:
  * command line: `servo.k_position=0.5:4` (a range), `servo.k_position=0.5:4:log` (sampled on a
    log scale), `fitness.combine=mean,min` (choices);
  * TOML (`--space-file TUNE.toml`):
        [tune.space]
        "servo.k_position" = { low = 0.5, high = 4.0, log = true }
        "tracker.generations_per_frame" = { low = 4, high = 12 }
        "fitness.combine" = { choices = ["mean", "min"] }
    or the short forms `"servo.k_position" = [0.5, 4.0]` (a range) and `{ choices = [...] }`.

A range's type follows the key's: an integer key samples integers, a float key floats. Both ends
of a range and every choice must be values the configuration accepts (its types and its range
checks, e.g. [servo] k_position > 0): an unknown key or an out-of-bounds end is an InputError
naming it, so a study never starts with a space it cannot run.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from photoservo.config import load_config, load_config_dict
from photoservo.errors import InputError
from photoservo.tomlconf import _toml_value as toml_value, read_toml


@dataclass(frozen=True)
class Param:
    """One tuned config key: a numeric range [low, high] (int or float, optionally log-scaled)
    or a list of choices."""

    key: str                        # "section.name", as `--set` spells it
    kind: str                       # "float", "int" or "choice"
    low: float | int | None = None
    high: float | int | None = None
    log: bool = False
    choices: tuple[Any, ...] = ()

    def distribution(self) -> Any:
        """The Optuna distribution of this parameter."""
        from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution

        if self.kind == "choice":
            return CategoricalDistribution(self.choices)
        if self.kind == "int":
            return IntDistribution(int(self.low), int(self.high), log=self.log)
        return FloatDistribution(float(self.low), float(self.high), log=self.log)

    def describe(self) -> str:
        if self.kind == "choice":
            return f"{self.key} in {{{', '.join(map(str, self.choices))}}}"
        return f"{self.key} in [{self.low}, {self.high}]" + (" (log)" if self.log else "")


def overrides(params: dict[str, Any]) -> list[str]:
    """{key: value} -> ['key=value', ...] in `--set` syntax."""
    return [f"{k}={toml_value(v)}" for k, v in params.items()]


def _default_value(key: str, where: str) -> Any:
    """The key's value in the default configuration (an InputError when there is no such key)."""
    node: Any = load_config_dict()
    parts = key.split(".")
    for i, k in enumerate(parts):
        if not isinstance(node, dict) or k not in node:
            raise InputError(f"{where}: unknown config key '{'.'.join(parts[: i + 1])}'")
        node = node[k]
    if isinstance(node, dict):
        raise InputError(f"{where}: '{key}' is a section, not a key")
    return node


def _check_value(key: str, value: Any, where: str, base: Sequence[str]) -> None:
    """The configuration accepts `key = value` on top of the base overrides (types and bounds)."""
    try:
        load_config(None, [*base, f"{key}={toml_value(value)}"])
    except InputError as e:
        raise InputError(f"{where}: {e}") from None


def make_param(key: str, *, low: Any = None, high: Any = None, log: bool = False,
               choices: Sequence[Any] | None = None, where: str, base: Sequence[str] = ()) -> Param:
    """A validated Param: the key exists, the range is ordered and both ends (or every choice)
    pass the configuration's checks on top of `base` (--set overrides)."""
    default = _default_value(key, where)
    if choices is not None:
        if not choices:
            raise InputError(f"{where}: no choices for '{key}'")
        for c in choices:
            _check_value(key, c, where, base)
        return Param(key, "choice", choices=tuple(choices))
    if isinstance(default, bool) or not isinstance(default, (int, float)):
        raise InputError(f"{where}: '{key}' is not a number (default {default!r}): give choices (a,b,c)")
    is_int = isinstance(default, int)
    for name, v in (("low", low), ("high", high)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InputError(f"{where}: '{key}' {name} must be a finite number, got {v!r}")
        if is_int and v != int(v):
            raise InputError(f"{where}: '{key}' is an integer key, {name} {v!r} is not an integer")
    if not low < high:
        raise InputError(f"{where}: '{key}' range {low}:{high} is empty (low must be below high)")
    if log and low <= 0:
        raise InputError(f"{where}: '{key}' log scale needs low > 0, got {low}")
    low, high = (int(low), int(high)) if is_int else (float(low), float(high))
    _check_value(key, low, where, base)
    _check_value(key, high, where, base)
    return Param(key, "int" if is_int else "float", low, high, log=log)


def _parse_scalar(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        return text.strip()


def parse_space_arg(text: str, base: Sequence[str] = ()) -> Param:
    """'key=lo:hi', 'key=lo:hi:log' or 'key=a,b,c' (the --space option) -> Param."""
    where = f"--space '{text}'"
    if "=" not in text:
        raise InputError(f"{where}: expected key=low:high or key=a,b,c")
    key, spec = (s.strip() for s in text.split("=", 1))
    if ":" in spec:
        parts = spec.split(":")
        log = len(parts) == 3 and parts[2].strip() == "log"
        if len(parts) != 2 and not log:
            raise InputError(f"{where}: expected low:high or low:high:log")
        return make_param(key, low=_parse_scalar(parts[0]), high=_parse_scalar(parts[1]), log=log,
                          where=where, base=base)
    if "," in spec:
        return make_param(key, choices=[_parse_scalar(c) for c in spec.split(",")], where=where, base=base)
    raise InputError(f"{where}: expected key=low:high or key=a,b,c")


def load_space_file(path: str | Path, base: Sequence[str] = ()) -> list[Param]:
    """The [tune.space] table of a TOML file (module docstring) -> Params."""
    doc = read_toml(Path(path))
    space = doc.get("tune", {}).get("space") if isinstance(doc.get("tune"), dict) else None
    if not isinstance(space, dict) or not space:
        raise InputError(f"{path}: no [tune.space] table")
    out = []
    for key, spec in space.items():
        where = f"{path}: [tune.space] '{key}'"
        if isinstance(spec, list) and len(spec) == 2:
            out.append(make_param(key, low=spec[0], high=spec[1], where=where, base=base))
        elif isinstance(spec, dict) and "choices" in spec and set(spec) == {"choices"}:
            out.append(make_param(key, choices=list(spec["choices"]), where=where, base=base))
        elif isinstance(spec, dict) and {"low", "high"} <= set(spec) <= {"low", "high", "log"}:
            out.append(make_param(key, low=spec["low"], high=spec["high"], log=bool(spec.get("log", False)),
                                  where=where, base=base))
        else:
            raise InputError(f"{where}: expected [low, high], {{ low, high, log }} or {{ choices = [...] }}")
    return out


def build_space(args_space: Sequence[str], space_file: str | Path | None, base: Sequence[str] = ()) -> list[Param]:
    """The study's space: the file's keys, then --space (a key given twice is an error)."""
    params = list(load_space_file(space_file, base)) if space_file else []
    params += [parse_space_arg(s, base) for s in args_space]
    if not params:
        raise InputError("no search space: give --space key=low:high (or key=a,b,c) or --space-file TUNE.toml")
    seen: set[str] = set()
    for p in params:
        if p.key in seen:
            raise InputError(f"search space: '{p.key}' given twice")
        seen.add(p.key)
    return params


def overlay_toml(params: dict[str, Any], header: str = "") -> str:
    """A config overlay (only the tuned keys, grouped by section) that `--config` takes."""
    sections: dict[str, list[str]] = {}
    for key, v in params.items():
        section, name = key.rsplit(".", 1)
        sections.setdefault(section, []).append(f"{name} = {toml_value(v)}")
    body = "\n\n".join(f"[{s}]\n" + "\n".join(lines) for s, lines in sections.items())
    return (header + "\n" if header else "") + body + "\n"
