"""Typed TOML tables: a frozen dataclass built from a TOML table, each key checked against the
field's type hint; unknown, missing and wrongly typed keys are InputErrors that name the key.
Shared by servo/config.py (the application config) and robot/pa10.py (the arm's limits file).
"""

from __future__ import annotations

import dataclasses
import tomllib
import types
import typing
from pathlib import Path
from typing import Any

from photoservo.errors import InputError


def configs_dir() -> Path:
    """Folder holding the shipped TOML files (default.toml, pa10.toml, example rigs...): the
    checkout's `configs/` when running from a source tree, else the installed package data."""
    pkg = Path(__file__).resolve().parent
    checkout = pkg.parent / "configs"
    if (checkout / "default.toml").is_file():
        return checkout
    return pkg / "configs"  # where the wheel puts them (pyproject maps configs/ -> photoservo.configs)


def read_toml(path: Path) -> dict:
    try:
        text = path.read_text()
    except OSError as e:
        raise InputError(f"{path}: cannot read config ({e.strerror or e})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{path}: not valid TOML ({e})") from None


def _coerce(value: Any, hint: Any, key: str) -> Any:
    """Check `value` against a field's type hint; ints are accepted for floats, lists for tuples."""
    origin = typing.get_origin(hint)
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"config key '{key}': expected a number, got {value!r}")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise InputError(f"config key '{key}': expected an integer, got {value!r}")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise InputError(f"config key '{key}': expected true or false, got {value!r}")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise InputError(f"config key '{key}': expected a string, got {value!r}")
        return value
    if origin is typing.Literal:
        if value not in typing.get_args(hint):
            allowed = ", ".join(repr(a) for a in typing.get_args(hint))
            raise InputError(f"config key '{key}': {value!r} is not one of {allowed}")
        return value
    if origin in (list, tuple):
        if not isinstance(value, list):
            raise InputError(f"config key '{key}': expected a list, got {value!r}")
        args = typing.get_args(hint)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise InputError(f"config key '{key}': expected {len(args)} values, got {len(value)}")
            return tuple(_coerce(v, a, f"{key}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
        item = args[0] if args else Any
        vals = [v if item is Any else _coerce(v, item, f"{key}[{i}]") for i, v in enumerate(value)]
        return tuple(vals) if origin is tuple else vals
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(hint)
        if value is None and type(None) in args:
            return None
        for a in args:
            if a is type(None):
                continue
            try:
                return _coerce(value, a, key)
            except InputError:
                pass
        raise InputError(f"config key '{key}': {value!r} has the wrong type")
    if dataclasses.is_dataclass(hint):
        if not isinstance(value, dict):
            raise InputError(f"config key '{key}': expected a table")
        return build_dataclass(hint, value, key)
    return value


def build_dataclass(cls: type, table: dict, where: str) -> Any:
    """Instantiate dataclass `cls` from a TOML table, validating every key by its type hint.
    A class may define `validate(self, where)` for range checks (raise InputError)."""
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    def key(n: str) -> str:
        return f"{where}.{n}" if where else n

    for k in table:
        if k not in names:
            raise InputError(f"config: unknown key '{key(k)}'")
    kwargs = {}
    for n in names:
        if n not in table:
            raise InputError(f"config: missing key '{key(n)}'")
        kwargs[n] = _coerce(table[n], hints[n], key(n))
    obj = cls(**kwargs)
    check = getattr(obj, "validate", None)
    if callable(check):
        check(where)
    return obj


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if v is None:
        return '"none"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(type(v))


def dump_config(cfg: Any, prefix: str = "") -> str:
    """The effective config as TOML text (what `photoservo config show` prints)."""
    scalars, tables = [], []
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if dataclasses.is_dataclass(v):
            tables.append(dump_config(v, f"{prefix}{f.name}."))
        else:
            scalars.append(f"{f.name} = {_toml_value(v)}")
    head = [f"[{prefix[:-1]}]"] if prefix and scalars else []
    body = "\n".join(head + scalars)
    return "\n\n".join(x for x in [body] + tables if x)
