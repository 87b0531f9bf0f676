"""The package's docstring examples are tests too (issue 11): every module of photoservo, as
imported - from the installed package in CI, from the tree in development. (Collecting the
source files with pytest's --doctest-modules instead fails on an installed package: the
modules it finds in the tree are not the ones already imported from site-packages.)"""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import photoservo

MODULES = sorted(m.name for m in pkgutil.walk_packages(photoservo.__path__, "photoservo.")
                 if not m.name.endswith("__main__"))  # __main__ runs the CLI when imported


def test_the_walk_finds_the_modules_that_hold_examples():
    assert {"photoservo.geometry", "photoservo.robot.pa10", "photoservo.sim.renderer"} <= set(MODULES)


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name: str):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, report=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples in {name} failed (run: python -m doctest -v)"
