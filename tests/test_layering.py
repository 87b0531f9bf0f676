"""The package layering of DESIGN.md, read from the source's imports (every import statement,
also those inside functions): data flows one way, so

  * vision/ and robot/ reach none of servo/, sim/, record/, cli/ (not even through another
    module, e.g. the application config, which gathers every section);
  * sim/ stands in for the world with vision/ and robot/: its world models reach none of servo/,
    record/, cli/; only sim/run.py, the harness that runs the product loop on them, imports
    servo/ (and, like servo/ itself, no record/ or cli/ module);
  * servo/, the product loop, imports nothing of sim/, record/, cli/ (it reaches the config's
    sections of those only through the application config);
  * nothing outside cli/ imports cli/.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "photoservo"


def _module_name(path: Path) -> str:
    parts = path.relative_to(PKG.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
    """photoservo modules that the file imports (absolute names; `from pkg import mod` counts
    as importing pkg.mod when that is a module)."""
    mod = _module_name(path)
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative import
                base = mod.split(".")[: len(mod.split(".")) - node.level + (path.name == "__init__.py")]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            out.add(name)
            out |= {f"{name}.{a.name}" for a in node.names}
    return {m for m in out if m == "photoservo" or m.startswith("photoservo.")}


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    files = {_module_name(p): p for p in PKG.rglob("*.py")}
    return {m: {i for i in _imports(p) if i in files and i != m} for m, p in files.items()}


def _reach(graph: dict[str, set[str]], start: str) -> dict[str, str]:
    """Every module reachable from `start`, each with the module that first imports it."""
    seen: dict[str, str] = {}
    todo = [start]
    while todo:
        m = todo.pop()
        for i in sorted(graph[m]):
            if i not in seen and i != start:
                seen[i] = m
                todo.append(i)
    return seen


def _chain(seen: dict[str, str], start: str, end: str) -> str:
    path = [end]
    while path[-1] != start:
        path.append(seen[path[-1]])
    return " -> ".join(reversed(path))


def _package(m: str) -> str:
    return m.split(".")[1] if m.count(".") >= 1 else ""


RULES = {  # package -> packages it must not reach, directly or through other modules
    "vision": {"servo", "sim", "record", "cli"},
    "robot": {"servo", "sim", "record", "cli"},
    "sim": {"servo", "record", "cli"},
}
HARNESS = "photoservo.sim.run"  # the one sim/ module that runs servo/'s loop
DIRECT = {  # module or package -> packages it must not import directly
    HARNESS: {"record", "cli"},
    "servo": {"sim", "record", "cli"},
}


def test_the_graph_is_read(graph):
    assert "photoservo.vision.tracker" in graph and "photoservo.robot.pa10" in graph
    assert "photoservo.vision.estimator" in graph["photoservo.vision.tracker"]  # an import it has


@pytest.mark.parametrize("pkg", sorted(RULES))
def test_lower_packages_reach_no_higher_one(graph, pkg):
    bad = []
    for m in sorted(graph):
        if _package(m) != pkg or m == HARNESS:
            continue
        seen = _reach(graph, m)
        bad += [_chain(seen, m, i) for i in sorted(seen) if _package(i) in RULES[pkg]]
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("who", sorted(DIRECT))
def test_the_loop_and_its_harness_import_no_higher_package(graph, who):
    mods = [m for m in graph if m == who or _package(m) == who]
    assert mods
    bad = [f"{m} -> {i}" for m in sorted(mods) for i in sorted(graph[m]) if _package(i) in DIRECT[who]]
    assert not bad, "\n".join(bad)


def test_nothing_imports_the_cli(graph):
    bad = [f"{m} -> {i}" for m, imps in sorted(graph.items()) if _package(m) != "cli"
           for i in sorted(imps) if _package(i) == "cli"]
    assert not bad, "\n".join(bad)


def test_the_check_catches_an_indirect_import():
    g = {"photoservo.vision.a": {"photoservo.config"}, "photoservo.config": {"photoservo.servo.b"},
         "photoservo.servo.b": set()}
    seen = _reach(g, "photoservo.vision.a")
    assert _chain(seen, "photoservo.vision.a", "photoservo.servo.b") == \
        "photoservo.vision.a -> photoservo.config -> photoservo.servo.b"
