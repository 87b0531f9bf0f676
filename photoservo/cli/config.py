"""photoservo config show [--config CFG.toml] [--set section.key=value ...]

Prints the effective configuration (defaults <- file <- overrides) as TOML, after the same
checks every verb makes (types, bounds: configs/default.toml documents each key).

Examples:
    photoservo config show
    photoservo config show --config site.toml --set ga.population=60
"""

from __future__ import annotations

import argparse

from photoservo.cli.options import add_config_options
from photoservo.config import load_config
from photoservo.tomlconf import dump_config


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("action", choices=["show"], help="show: print the effective configuration")
    add_config_options(p)


def run(args: argparse.Namespace) -> int:
    print(dump_config(load_config(args.config, args.overrides)))
    return 0
