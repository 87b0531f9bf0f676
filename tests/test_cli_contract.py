"""The CLI contract over every verb (issue 12): bad input -> exit status 2, exactly one line on
stderr naming the problem, no traceback, nothing written. In process (fast) for the tables,
hypothesis over numeric arguments and config overrides, and a few rows as a new user runs them
(a subprocess of `python -m photoservo.cli`)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from photoservo.cli.main import VERBS, main
from photoservo.tomlconf import configs_dir, read_toml

ROOT = Path(__file__).resolve().parents[1]
S = ROOT / "examples" / "scene"
STEREO = ["--rig", str(S / "rig.toml"), "--photo", str(S / "photo.png"), "--left", str(S / "left.png"),
          "--right", str(S / "right.png")]
NOPE = "/nonexistent/x"

# verb -> bad command lines, each with a word the one line must contain
BAD: dict[str, list[tuple[list[str], str]]] = {
    "track": [(["--duration", "0"], "--duration"), (["--duration", "inf"], "finite"),
              (["--seed", "-1"], "--seed"), (["--rt-priority", "0"], "--rt-priority"),
              (["--set", "ga.population=1000000000000"], "ga.population"),
              (["--set", "motion.tool_speed_max_mm_s=inf"], "tool_speed_max_mm_s"),
              (["--config", NOPE], NOPE), (["--record", "a.rrd", "--no-record"], "not allowed"),
              (["--bogus"], "--bogus"), (["--sim", "--port", "/dev/null"], "--sim")],
    "estimate": [(STEREO + ["--seed", "-1"], "--seed"), (STEREO + ["--preview", "out.xyz"], ".xyz"),
                 (STEREO + ["--preview", "/tmp"], "folder"), (STEREO[:2] + ["--photo", str(S)] + STEREO[4:], "folder"),
                 (STEREO[:6] + ["--right", NOPE], NOPE), (STEREO + ["--roi", "1,2,3"], "--roi"),
                 (STEREO[2:], "--rig"), (STEREO + ["--set", "ga.elite=-1"], "ga.elite")],
    "model": [(["--photo", NOPE], NOPE), (["--photo", str(S / "photo.png"), "--preview", "x.txt"], ".txt"),
              (["--photo", str(S / "rig.toml")], "not a readable image")],
    "synth": [(["--specimen", "squid", "--seed", "-1", "--out", "x"], "--seed"),
              (["--specimen", "eel", "--out", "x"], "eel"),
              (["--specimen", "squid", "--distance", "nan", "--out", "x"], "finite"),
              (["--specimen", "squid", "--effects", "snow", "--out", "x"], "snow")],
    "scan": [(STEREO + ["--pose", str(S / "truth.json"), "--out", "x", "--steps", "2"], "--steps"),
             (STEREO + ["--pose", str(S / "truth.json"), "--out", "x", "--axes", "w"], "--axes"),
             (STEREO + ["--pose", NOPE, "--out", "x"], NOPE)],
    "calibrate": [(["board", "--board", "10000x10000", "--square-mm", "25", "--out", "b.png"], "100"),
                  (["board", "--board", "9x6", "--square-mm", "-1", "--out", "b.png"], "square"),
                  (["board", "--board", "9", "--square-mm", "25", "--out", "b.png"], "COLSxROWS"),
                  (["stereo", "--left", NOPE, "--right", NOPE, "--board", "9x6", "--square-mm", "25"], NOPE),
                  (["hand-eye", "--rig", NOPE, "--views", NOPE, "--board", "9x6", "--square-mm", "25"], NOPE),
                  (["water", "--rig", str(S / "rig.toml"), "--views", "x", "--board", "9x6", "--square-mm", "25"],
                   "hand_eye"),
                  (["capture", "--out", "x", "--interval", "-1"], "--interval"),
                  (["capture", "--videos", NOPE, NOPE, "--out", "x", "--count", "1"], NOPE),
                  (["frobnicate"], "frobnicate")],
    "replay": [([NOPE], NOPE), ([str(S / "rig.toml")], "rig.toml")],
    "move": [(["--port", NOPE, "--home"], NOPE), (["--port", NOPE, "--joints", "1", "2"], "--joints"),
             (["--port", NOPE, "--home", "--speed", "0"], "--speed"),
             (["--port", NOPE, "--joints", *["nan"] * 7], "finite"),
             (["--port", NOPE, "--joints", "0", "95", "0", "60", "0", "90", "0"], "S2")],
    "pa10-sim": [(["--drop", "1.5"], "--drop"), (["--baud", "-1"], "--baud"),
                 (["--seed", "x"], "--seed"), (["--set", "emulator.state_hz=500"], "state_hz")],
    "tune": [(["--space", "servo.k_position=x"], "--space"), (["--space", "nosuch.key=0:1"], "nosuch"),
             ([], "no search space")],
    "config": [(["show", "--set", "nosuch.key=1"], "nosuch"), (["show", "--set", "ga.population"], "ga.population"),
               (["list"], "list")],
}


def _one_line(rc: int, err: str, word: str, argv: list[str]) -> None:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, (argv, rc, err)
    assert len(lines) == 1, (argv, err)
    assert "Traceback" not in err and word in lines[0], (argv, err)


def test_every_verb_has_a_table():
    assert set(VERBS) <= set(BAD) | {"find-cameras", "find-port"}


@pytest.mark.parametrize("verb, argv, word", [(v, a, w) for v, rows in BAD.items() for a, w in rows])
def test_bad_input_is_one_line_exit_2(verb, argv, word, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # nothing may be written; check the folder stays empty
    rc = main([verb, *argv])
    cap = capsys.readouterr()
    _one_line(rc, cap.err, word, [verb, *argv])
    assert list(tmp_path.iterdir()) == [], "a refused command wrote files"


@pytest.mark.parametrize("argv, word", [
    (["estimate", "--seed", "-1", *STEREO], "--seed"),
    (["calibrate", "board", "--board", "10000x10000", "--square-mm", "25", "--out", "b.png"], "100"),
    (["config", "show", "--set", "ga.population=1000000000000"], "ga.population"),
    (["track", "--view", "--sim", "--duration", "1"], "--view"),
])
def test_as_a_new_user_runs_it(argv, word, tmp_path):
    env = {k: v for k, v in __import__("os").environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = subprocess.run([sys.executable, "-m", "photoservo.cli", *argv], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=120)
    _one_line(r.returncode, r.stderr, word, argv)
    assert r.stdout == "" and list(tmp_path.iterdir()) == []


SETTINGS = settings(max_examples=60, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])
NUM_TEXT = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.integers(-10**20, 10**20).map(str),
                     st.sampled_from(["", "x", "1e999", "-0", "0x10", "1_000"]))


@SETTINGS
@given(joints=st.lists(NUM_TEXT, min_size=7, max_size=7), speed=NUM_TEXT)
def test_move_arguments_never_crash(joints, speed, capsys):
    """Any joints and speed against a port that does not exist: always refused before the port,
    or at it, with one line."""
    rc = main(["move", "--port", NOPE, "--joints", *joints, "--speed", speed, "--no-record"])
    cap = capsys.readouterr()
    _one_line(rc, cap.err, "", ["move"])


def _config_keys():
    doc = read_toml(configs_dir() / "default.toml")
    return sorted(f"{s}.{k}" for s, t in doc.items() for k in t)


VALUES = st.one_of(NUM_TEXT, st.sampled_from(["true", '"abc"', "[1, 2]", "[1e400, 0]", "nan", "-inf", "{}"]))


@SETTINGS
@given(key=st.sampled_from(_config_keys()), value=VALUES)
def test_any_config_override_is_accepted_or_one_line(key, value, capsys):
    """Every key, any value: either a valid config (exit 0, and every number in it finite unless
    it means unknown) or one line naming the key (exit 2)."""
    rc = main(["config", "show", "--set", f"{key}={value}"])
    cap = capsys.readouterr()
    if rc == 0:
        import tomllib

        shown = tomllib.loads(cap.out)
        sec, k = key.split(".")
        v = shown[sec][k]
        for x in v if isinstance(v, list) else [v]:
            assert not isinstance(x, float) or math.isfinite(x) or key == "tracker.water_z_mm", (key, value, x)
    else:
        _one_line(rc, cap.err, key.split(".")[0], [key, value])


def test_json_outputs_are_strict(capsys):
    """--json output parses with a parser that rejects NaN and Infinity."""
    def strict(text: str):
        return json.loads(text, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))

    # contrast and both appearance cues are <= 1: no contrast passes and none is excused by the layout
    rc = main(["estimate", *STEREO, "--json",
               "--set", "estimator.min_contrast=1.5", "--set", "estimator.min_appearance=1.5"])
    out = capsys.readouterr().out
    assert rc == 1
    js = strict(out)
    assert js["found"] is False and js["position_mm"] is None


def _parsers():
    import argparse

    from photoservo.cli.main import build_parser

    for verb in VERBS:
        top = build_parser(verb)
        sub = next(a for a in top._actions if isinstance(a, argparse._SubParsersAction)).choices[verb]
        yield verb, sub
        for a in sub._actions:
            if isinstance(a, argparse._SubParsersAction):
                for name, p in a.choices.items():
                    yield f"{verb} {name}", p


@pytest.mark.parametrize("verb, parser", list(_parsers()), ids=lambda x: x if isinstance(x, str) else "")
def test_help_has_examples_and_every_flag_has_text(verb, parser):
    text = (parser.description or "") + (parser.epilog or "")
    if " " not in verb:  # a verb's --help shows its module docstring with examples
        assert "Example" in text and "photoservo " + verb.split()[0] in text, verb
    for a in parser._actions:
        if a.option_strings and a.help is not argparse_suppress():
            assert a.help and a.help.strip(), f"{verb}: {a.option_strings} has no help text"


def argparse_suppress():
    import argparse

    return argparse.SUPPRESS


def test_a_rig_with_the_baseline_sign_swapped_gets_a_hint(tmp_path, caplog):
    """T x > 0 (the right camera LEFT of the left one) is nearly always a swapped sign: the
    search would then find nothing, so the loader says so, naming the file and T."""
    import argparse
    import logging

    from photoservo.cli.options import load_stereo_inputs
    from photoservo.config import load_config
    from photoservo.vision.rig import Rig, load_rig, save_rig

    rig = load_rig(S / "rig.toml")
    assert rig.T[0] < 0
    swapped = tmp_path / "swapped.toml"
    save_rig(Rig(rig.left, rig.right, rig.R, -rig.T, rig.hand_eye), swapped)
    args = argparse.Namespace(rig=str(swapped), photo=str(S / "photo.png"), roi=None, left=str(S / "left.png"),
                              right=str(S / "right.png"))
    with caplog.at_level(logging.WARNING):
        load_stereo_inputs(args, load_config())
    assert any("swapped.toml" in r.message and "T x = +" in r.message and "sign" in r.message
               for r in caplog.records), caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        load_stereo_inputs(argparse.Namespace(**{**vars(args), "rig": str(S / "rig.toml")}), load_config())
    assert not caplog.records


def test_progress_is_drawn_on_a_terminal_and_silent_in_a_log(tmp_path):
    """scan's progress bar on a real pty (tqdm's \\r updates, 100 %), and nothing of it when
    stderr is a file: the issue's `2>log; grep -c $'\\r' log` gives 0."""
    import os
    import pty

    argv = [sys.executable, "-m", "photoservo.cli", "scan", *STEREO, "--pose", str(S / "truth.json"),
            "--axes", "z", "--steps", "5"]
    import fcntl
    import struct
    import termios

    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # a terminal's size
    r = subprocess.run(argv + ["--out", str(tmp_path / "a")], stderr=slave, stdout=subprocess.DEVNULL, timeout=300)
    os.close(slave)
    seen = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:
            break
        if not chunk:
            break
        seen += chunk
    os.close(master)
    assert r.returncode == 0 and b"\r" in seen and b"100%" in seen, seen[-300:]
    with open(tmp_path / "log", "w") as log:
        r = subprocess.run(argv + ["--out", str(tmp_path / "b")], stderr=log, stdout=subprocess.DEVNULL, timeout=300)
    text = (tmp_path / "log").read_text()
    assert r.returncode == 0 and text.count("\r") == 0 and "%" not in text, text
