"""photoservo config show [--config CFG.toml] [--set section.key=value ...]

Prints the effective configuration (defaults <- file <- overrides) as TOML."""

from __future__ import annotations

import argparse

from photoservo.config import load_config
from photoservo.tomlconf import dump_config


def add_config_options(p: argparse.ArgumentParser) -> None:
    """--config and --set, shared by every verb that reads the configuration."""
    p.add_argument("--config", metavar="CFG.toml", help="config file with the keys to change")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override one key, e.g. --set ga.population=60 (repeatable)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("action", choices=["show"], help="show: print the effective configuration")
    add_config_options(p)


def run(args: argparse.Namespace) -> int:
    print(dump_config(load_config(args.config, args.overrides)))
    return 0
