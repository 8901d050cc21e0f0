"""The `chaingen` command as a user runs it: a subprocess, its exit status, stdout and stderr.

Bad input (scene files and command-line values) must give exit status 2 and one clear line on
stderr that names what is wrong and where, no traceback, and nothing half-written on disk.
Most bad-input cases fail before any code generation, so they are cheap; the good runs share
the session's build cache (CHAINGEN_CACHE_DIR, set in conftest.py and inherited here).
"""
from __future__ import annotations

import csv
import json
import math
import os
import re
import subprocess
import tomllib
from pathlib import Path

import pytest

from helpers import ROOT, chaingen, chaingen_in_process

MONO = ROOT / "scenes" / "three_link_mono.toml"
GRAVITY = ROOT / "scenes" / "three_link_gravity.toml"
MONO_TEXT = MONO.read_text()

HEADER = "t,phi1,phi2,phi3,omega1,omega2,omega3,energy,constraint_error"
EXIT_BAD_INPUT = 2
EXIT_FAILED = 1


# -- helpers ---------------------------------------------------------------------------------

def edited(*edits) -> str:
    """three_link_mono.toml with text edits (old, new), old unique, or (old, new, occurrence)."""
    text = MONO_TEXT
    for old, new, *rest in edits:
        if rest:
            occurrence = rest[0]
        else:
            occurrence = 0
            assert text.count(old) == 1, f"test setup: {old!r} must occur exactly once"
        index = -1
        for _ in range(occurrence + 1):
            index = text.find(old, index + 1)
            assert index >= 0, f"test setup: {old!r} occurs fewer than {occurrence + 1} times"
        text = text[:index] + new + text[index + len(old):]
    return text


def snapshot(directory: Path) -> set[str]:
    """Every file and directory below `directory`, hidden ones included."""
    return {str(path.relative_to(directory)) for path in directory.rglob("*")}


def error_line(result: subprocess.CompletedProcess, *, usage_allowed: bool = False) -> str:
    """The error message of a bad-input run, after checking the bad-input rules.

    Exit status 2, no traceback, nothing on stdout, and exactly one non-empty line on stderr;
    with `usage_allowed` (values argparse rejects) also the usage lines argparse prints
    before its one error line.
    """
    report = f"exit {result.returncode}\nstdout:\n{result.stdout}\nstderr:\n{result.stderr}"
    assert result.returncode == EXIT_BAD_INPUT, report
    assert "Traceback" not in result.stderr, report
    assert result.stdout == "", report
    lines = result.stderr.splitlines()
    if usage_allowed and lines and lines[0].startswith("usage:"):
        assert lines[-1].startswith("chaingen "), report
        lines = lines[-1:]
    assert len(lines) == 1 and lines[0].strip(), report
    assert "error" in lines[0], report
    return lines[0]


def assert_names(message: str, *fragments: str) -> None:
    for fragment in fragments:
        assert fragment in message, f"{fragment!r} not in {message!r}"


# -- bad scene files -------------------------------------------------------------------------

HALF_PI = repr(math.pi / 2)

# (id, edits of three_link_mono.toml, key path, further fragments of the message)
BAD_SCENES = [
    # unknown keys
    ("unknown top-level key", [("gravity = 1.0", "gravity = 1.0\ngravty = 2.0")],
     "gravty", ["unknown key", "'gravity'"]),
    ("unknown key in base", [("fastening = 0.4", "fastening = 0.4\noffset = 0.1", 0)],
     "base.offset", ["unknown key"]),
    ("unknown key in a link", [("com = 0.5", "com = 0.5\ncom_norml = 0.1", 1)],
     "links[1].com_norml", ["unknown key", "'com_normal'"]),
    ("unknown key in a spring",
     [("rest_length = 0.2", "rest_length = 0.2\nrestlength = 0.3", 2)],
     "springs[2].restlength", ["unknown key", "'rest_length'"]),
    ("unknown key in initial",
     [("velocities = [0.0, 0.0, 0.0]", "velocities = [0.0, 0.0, 0.0]\naccel = [0, 0, 0]")],
     "initial.accel", ["unknown key"]),
    ("unknown key in simulation", [("t_end = 50.0", "t_end = 50.0\nsteps = 100")],
     "simulation.steps", ["unknown key"]),
    ("actuated joint beyond the chain",
     [("[initial]", "[actuation]\njoints = [1, 4]\n\n[initial]")],
     "actuation.joints[1]", ["joint 4 does not exist", "3 joints"]),
    # wrong types
    ("string mass", [("mass = 1.0", 'mass = "1.0"', 0)], "links[0].mass",
     ["must be a number", "not a string"]),
    ("bool gravity", [("gravity = 1.0", "gravity = true")], "gravity",
     ["must be a number", "not a boolean"]),
    ("string angle", [("angles = [0.7853981633974483, 0.3, 0.3]", 'angles = [0.78, "0.3", 0.3]')],
     "initial.angles[1]", ["must be a number"]),
    # non-finite numbers
    ("nan inertia", [("inertia = 1.0", "inertia = nan", 2)], "links[2].inertia",
     ["must be finite", "got nan"]),
    ("inf gravity", [("gravity = 1.0", "gravity = inf")], "gravity", ["must be finite", "got inf"]),
    ("-inf stiffness", [("stiffness = 1.0", "stiffness = -inf", 0)], "springs[0].stiffness",
     ["must be finite"]),
    ("nan initial angle",
     [("angles = [0.7853981633974483, 0.3, 0.3]", "angles = [0.78, 0.3, nan]")],
     "initial.angles[2]", ["must be finite"]),
    ("inf dt", [("\ndt = 0.01", "\ndt = inf")], "simulation.dt", ["must be finite"]),
    # out of range
    ("mass zero", [("mass = 1.0", "mass = 0.0", 0)], "links[0].mass", ["must be > 0", "got 0.0"]),
    ("mass negative", [("mass = 1.0", "mass = -1.0", 2)], "links[2].mass",
     ["must be > 0", "got -1.0"]),
    ("negative inertia", [("inertia = 1.0", "inertia = -0.5", 1)], "links[1].inertia",
     ["must be >= 0", "got -0.5"]),
    ("length zero", [("length = 1.0", "length = 0", 1)], "links[1].length",
     ["must be > 0", "got 0.0"]),
    ("negative damping", [("com = 0.5", "com = 0.5\ndamping = -0.1", 0)], "links[0].damping",
     ["must be >= 0", "got -0.1"]),
    ("negative gravity", [("gravity = 1.0", "gravity = -9.81")], "gravity",
     ["must be >= 0", "got -9.81"]),
    ("negative stiffness", [("stiffness = 1.0", "stiffness = -1.0", 1)], "springs[1].stiffness",
     ["must be > 0", "got -1.0"]),
    ("zero stiffness", [("stiffness = 1.0", "stiffness = 0", 0)], "springs[0].stiffness",
     ["must be > 0"]),
    ("negative rest_length", [("rest_length = 0.2", "rest_length = -0.2", 0)],
     "springs[0].rest_length", ["must be >= 0", "got -0.2"]),
    ("dt zero", [("\ndt = 0.01", "\ndt = 0.0")], "simulation.dt", ["must be > 0", "got 0.0"]),
    ("dt negative", [("\ndt = 0.01", "\ndt = -0.01")], "simulation.dt", ["must be > 0"]),
    ("t_end zero", [("t_end = 50.0", "t_end = 0")], "simulation.t_end", ["must be > 0"]),
    ("t_end negative", [("t_end = 50.0", "t_end = -1.0")], "simulation.t_end", ["must be > 0"]),
    ("quadrature zero", [("quadrature = 3", "quadrature = 0")], "simulation.quadrature",
     ["from 1 to 20", "got 0"]),
    ("quadrature float", [("quadrature = 3", "quadrature = 3.0")], "simulation.quadrature",
     ["integer"]),
    ("unknown method", [('method = "es"', 'method = "bogus"')], "simulation.method",
     ['"es"', 'got "bogus"']),
    ("invalid name", [('name = "three-link-mono"', 'name = "three link"')], "name",
     ["must start with a letter"]),
    # list lengths and joints
    ("two angles for three links",
     [("angles = [0.7853981633974483, 0.3, 0.3]", "angles = [0.78, 0.3]")],
     "initial.angles", ["must have 3 entries", "not 2"]),
    ("four velocities for three links",
     [("velocities = [0.0, 0.0, 0.0]", "velocities = [0.0, 0.0, 0.0, 0.0]")],
     "initial.velocities", ["must have 3 entries", "not 4"]),
    ("spring offsets of wrong length",
     [("joints = [1, 1]", "joints = [1, 1]\noffsets = [0.4, 0.4, 0.4]")],
     "springs[0].offsets", ["must have 2 entries", "not 3"]),
    ("joints with three entries", [("joints = [1, 1]", "joints = [1, 2, 3]")],
     "springs[0].joints", ["two integers"]),
    ("spring over a joint that does not exist", [("joints = [2, 2]", "joints = [2, 4]")],
     "springs[1].joints", ["joint 4 does not exist", "3 joints"]),
    ("spring joints reversed", [("joints = [3, 3]", "joints = [3, 2]")],
     "springs[2].joints", ["after last joint"]),
    # P_1 = (0, r_1) = (0, 1) and P_2 = X_2 + 0 = (0, 1) at theta_1 = pi/2.
    ("zero-length spring segment",
     [("joints = [1, 1]", "joints = [1, 1]\noffsets = [1.0, 0.0]"),
      ("angles = [0.7853981633974483, 0.3, 0.3]", f"angles = [{HALF_PI}, 0.3, 0.3]")],
     "springs[0]", ["s_1", "zero length at the initial configuration"]),
    ("no links", [("[[links]]", "[[link]]", 0), ("[[links]]", "[[link]]", 0),
                  ("[[links]]", "[[link]]", 0)],
     "link", ["unknown key"]),
]


def write_scene(tmp_path: Path, text: str, name: str = "scene.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("edits, key, fragments",
                         [pytest.param(*case[1:], id=case[0]) for case in BAD_SCENES])
def test_bad_scene_simulate(tmp_path, edits, key, fragments):
    scene = write_scene(tmp_path, edited(*edits))
    out = tmp_path / "out.csv"
    before = snapshot(tmp_path)
    message = error_line(chaingen_in_process("simulate", scene, "--out", out, cwd=tmp_path))
    assert_names(message, f"{scene}: {key}", *fragments)
    assert not out.exists()
    assert snapshot(tmp_path) == before


GENERATE_CASES = ["unknown key in a link", "bool gravity", "nan inertia", "mass zero",
                  "two angles for three links", "spring over a joint that does not exist",
                  "zero-length spring segment", "unknown method"]
assert set(GENERATE_CASES) <= {case[0] for case in BAD_SCENES}


@pytest.mark.parametrize("edits, key, fragments",
                         [pytest.param(*case[1:], id=case[0]) for case in BAD_SCENES
                          if case[0] in GENERATE_CASES])
def test_bad_scene_generate(tmp_path, edits, key, fragments):
    scene = write_scene(tmp_path, edited(*edits))
    package = tmp_path / "pkg"
    before = snapshot(tmp_path)
    message = error_line(chaingen_in_process("generate", scene, "-o", package, cwd=tmp_path))
    assert_names(message, f"{scene}: {key}", *fragments)
    assert not package.exists()
    assert snapshot(tmp_path) == before


def toml_syntax_error_scene() -> tuple[str, int]:
    text = edited(("mass = 1.0", "mass = = 1.0", 1))
    line = text.splitlines().index("mass = = 1.0") + 1
    return text, line


@pytest.mark.parametrize("command", ["simulate", "generate"])
def test_toml_syntax_error_names_file_and_line(tmp_path, command):
    text, line = toml_syntax_error_scene()
    scene = write_scene(tmp_path, text)
    output = tmp_path / ("out.csv" if command == "simulate" else "pkg")
    option = "--out" if command == "simulate" else "-o"
    before = snapshot(tmp_path)
    message = error_line(chaingen(command, scene, option, output, cwd=tmp_path))
    assert_names(message, f"{scene}:{line}:", "TOML syntax error")
    assert line > 1
    assert not output.exists()
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("command", ["simulate", "generate"])
def test_missing_scene_file(tmp_path, command):
    scene = tmp_path / "no_such_scene.toml"
    output = tmp_path / ("out.csv" if command == "simulate" else "pkg")
    option = "--out" if command == "simulate" else "-o"
    message = error_line(chaingen(command, scene, option, output, cwd=tmp_path))
    assert_names(message, str(scene), "cannot read scene file")
    assert snapshot(tmp_path) == set()


def test_scene_file_that_is_a_directory(tmp_path):
    out = tmp_path / "out.csv"
    message = error_line(chaingen("simulate", tmp_path, "--out", out, cwd=tmp_path))
    assert_names(message, str(tmp_path), "cannot read scene file")
    assert snapshot(tmp_path) == set()


@pytest.mark.compile
@pytest.mark.parametrize("method", ["vi", "midpoint"])
def test_scene_method_selects_the_scheme(tmp_path, method):
    """[simulation].method picks the scheme; the trajectory file keeps its contract."""
    scene = write_scene(tmp_path, edited(('method = "es"', f'method = "{method}"')))
    out = tmp_path / "out.csv"
    result = chaingen("simulate", scene, "--t-end", "0.2", "--out", out, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert f"method {method}" in result.stdout
    header, rows = read_csv(out)
    assert header == ["t", "phi1", "phi2", "phi3", "omega1", "omega2", "omega3", "energy",
                      "constraint_error"]
    assert len(rows) == 21
    errors = [float(row[-1]) for row in rows]
    assert max(errors) <= (1e-13 if method == "vi" else 0.0)


@pytest.mark.heavy
@pytest.mark.parametrize("method", ["vi", "midpoint"])
def test_generate_method_option(tmp_path, method):
    result = chaingen("generate", MONO, "--method", method, "-o", "pkg", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    manifest = json.loads((tmp_path / "pkg" / "chaingen.json").read_text())
    assert manifest["method"] == method and manifest["prefix"] == f"three_link_mono_{method}"


# -- bad command-line values -----------------------------------------------------------------

# (id, options, option named, argparse rejects it (usage lines allowed), more fragments)
BAD_OPTIONS = [
    ("dt negative", ["--dt", "-1"], "--dt", False, ["must be > 0"]),
    ("dt nan", ["--dt", "nan"], "--dt", False, ["nan"]),
    ("dt inf", ["--dt", "inf"], "--dt", False, ["inf"]),
    ("dt zero", ["--dt", "0"], "--dt", False, []),
    ("dt not a number", ["--dt", "abc"], "--dt", True, ["'abc'"]),
    ("t-end zero", ["--t-end", "0"], "--t-end", False, ["must be > 0"]),
    ("t-end negative", ["--t-end", "-2"], "--t-end", False, []),
    ("t-end nan", ["--t-end", "nan"], "--t-end", False, []),
    ("every zero", ["--every", "0"], "--every", True, []),
    ("every not an integer", ["--every", "1.5"], "--every", True, []),
    ("quadrature zero", ["--quadrature", "0"], "--quadrature", True, []),
    ("quadrature too large", ["--quadrature", "21"], "--quadrature", False, ["21"]),
    ("method bogus", ["--method", "bogus"], "--method", True, ["'bogus'"]),
]


@pytest.mark.parametrize("options, option, argparse_error, fragments",
                         [pytest.param(*case[1:], id=case[0]) for case in BAD_OPTIONS])
def test_bad_simulate_option(tmp_path, options, option, argparse_error, fragments):
    out = tmp_path / "out.csv"
    result = chaingen_in_process("simulate", MONO, *options, "--out", out, cwd=tmp_path)
    message = error_line(result, usage_allowed=argparse_error)
    assert_names(message, option, *fragments)
    assert snapshot(tmp_path) == set()


@pytest.mark.parametrize("options, option, fragments", [
    pytest.param(["--quadrature", "0"], "--quadrature", [], id="quadrature zero"),
    pytest.param(["--quadrature", "x"], "--quadrature", [], id="quadrature not a number"),
    pytest.param(["--method", "bogus"], "--method", ["'bogus'"], id="method bogus"),
])
def test_bad_generate_option(tmp_path, options, option, fragments):
    package = tmp_path / "pkg"
    result = chaingen_in_process("generate", MONO, *options, "-o", package, cwd=tmp_path)
    assert_names(error_line(result, usage_allowed=True), option, *fragments)
    assert snapshot(tmp_path) == set()


def test_out_into_a_missing_directory(tmp_path):
    out = tmp_path / "no_such_dir" / "out.csv"
    message = error_line(chaingen("simulate", MONO, "--t-end", "0.1", "--out", out,
                                  cwd=tmp_path))
    assert_names(message, "--out", str(out.parent), "does not exist")
    assert snapshot(tmp_path) == set()


def test_out_is_a_directory(tmp_path):
    (tmp_path / "results").mkdir()
    message = error_line(chaingen("simulate", MONO, "--t-end", "0.1", "--out", "results",
                                  cwd=tmp_path))
    assert_names(message, "--out", "results", "is a directory")
    assert snapshot(tmp_path) == {"results"}


def test_generate_into_a_file(tmp_path):
    (tmp_path / "afile").write_text("keep me\n")
    message = error_line(chaingen("generate", MONO, "-o", "afile", cwd=tmp_path))
    assert_names(message, "afile", "not a directory")
    assert (tmp_path / "afile").read_text() == "keep me\n"
    assert snapshot(tmp_path) == {"afile"}


def test_generate_refuses_to_replace_an_unrelated_directory(tmp_path):
    (tmp_path / "work").mkdir()
    (tmp_path / "work" / "notes.txt").write_text("keep me\n")
    message = error_line(chaingen("generate", MONO, "-o", "work", cwd=tmp_path))
    assert_names(message, "work", "not a chaingen package")
    assert (tmp_path / "work" / "notes.txt").read_text() == "keep me\n"
    assert snapshot(tmp_path) == {"work", os.path.join("work", "notes.txt")}


@pytest.mark.parametrize("options", [["--dt", "1e-300", "--t-end", "1"],
                                     ["--dt", "1", "--t-end", "1e19"]],
                         ids=["dt 1e-300", "t-end 1e19"])
def test_step_count_too_large_is_bad_input(tmp_path, options):
    out = tmp_path / "out.csv"
    message = error_line(chaingen("simulate", GRAVITY, *options, "--out", out, cwd=tmp_path))
    assert "--dt" in message or "--t-end" in message, message
    assert snapshot(tmp_path) == set()


# -- good runs -------------------------------------------------------------------------------

def read_csv(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="") as stream:
        rows = list(csv.reader(stream))
    return rows[0], rows[1:]


@pytest.mark.compile
def test_simulate_writes_the_trajectory_file(tmp_path):
    out = tmp_path / "traj.csv"
    result = chaingen("simulate", GRAVITY, "--t-end", "0.5", "--out", out, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    with open(out) as stream:
        assert stream.readline().rstrip("\n") == HEADER
    header, rows = read_csv(out)
    assert ",".join(header) == HEADER
    assert len(rows) == 51
    assert all(len(row) == len(header) for row in rows)
    for row in rows:
        for field in row:
            value = float(field)
            assert math.isfinite(value), row
            assert f"{value:.17g}" == field, f"{field!r} is not written as %.17g"
    values = [[float(field) for field in row] for row in rows]

    scene = tomllib.loads(GRAVITY.read_text())
    first = values[0]
    assert first[0] == 0.0
    assert first[1:4] == pytest.approx(scene["initial"]["angles"], abs=1e-12, rel=0)
    assert first[4:7] == pytest.approx(scene["initial"]["velocities"], abs=1e-12, rel=0)
    times = [row[0] for row in values]
    assert times == pytest.approx([0.01 * k for k in range(51)], abs=1e-12, rel=0)
    assert all(-math.pi < row[j] <= math.pi for row in values for j in (1, 2, 3))
    energies = [row[7] for row in values]
    assert max(energies) - min(energies) < 1e-9     # es conserves energy to round-off
    assert max(row[8] for row in values) < 1e-9

    summary = result.stdout
    for fragment in ("steps", "50", "51 samples", "wall time", "t_realtime", "energy error",
                     "constraint error", "Newton iterations", str(out)):
        assert fragment in summary, f"{fragment!r} not in stdout:\n{summary}"
    # The trajectory and its metadata (scene, method, K, dt for `chaingen plot`), nothing else.
    assert snapshot(tmp_path) == {"traj.csv", "traj.csv.json"}
    meta = json.loads((tmp_path / "traj.csv.json").read_text())
    assert (meta["method"], meta["dt"], meta["n_steps"]) == ("es", 0.01, 50)


@pytest.mark.compile
def test_simulate_every_n(tmp_path):
    every_1, every_10 = tmp_path / "every1.csv", tmp_path / "every10.csv"
    for out, every in ((every_1, "1"), (every_10, "10")):
        result = chaingen("simulate", GRAVITY, "--t-end", "0.5", "--every", every,
                          "--out", out, cwd=tmp_path)
        assert result.returncode == 0, result.stderr
    header, rows = read_csv(every_10)
    assert ",".join(header) == HEADER
    times = [float(row[0]) for row in rows]
    assert len(rows) == 6
    assert times == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4, 0.5], abs=1e-12, rel=0)
    # the same samples as every 10th row of the full trajectory, digit for digit
    assert rows == read_csv(every_1)[1][::10]
    assert "every 10" in result.stdout


@pytest.mark.compile
def test_simulate_without_out_writes_nothing(tmp_path):
    result = chaingen("simulate", GRAVITY, "--t-end", "0.1", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "steps" in result.stdout
    assert snapshot(tmp_path) == set()


def test_generate_writes_the_package(tmp_path):
    package = tmp_path / "pkg"
    result = chaingen("generate", MONO, "-o", package, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    assert "pkg" in result.stdout
    assert package.is_dir()
    names = {path.name for path in package.iterdir()}
    assert {"Makefile", "CMakeLists.txt", "chaingen.json"} <= names
    assert any(name.endswith(".h") for name in names), names
    assert any(name.endswith(".c") for name in names), names
    manifest = json.loads((package / "chaingen.json").read_text())
    assert isinstance(manifest, dict)
    assert not any(name.startswith(".") for name in names)
    assert {path.name for path in tmp_path.iterdir()} == {"pkg"}   # no staging leftovers
    assert {"README.md", "example.c"} <= names
    assert manifest["sensitivities"] is True
    assert "three_link_mono_es_step_sensitivities" in (package / "three_link_mono_es.h").read_text()
    # The package directory gets the permissions of an ordinary new directory (umask).
    assert package.stat().st_mode & 0o777 == 0o777 & ~current_umask()


def test_generate_without_sensitivities(tmp_path):
    result = chaingen_in_process("generate", MONO, "--no-sensitivities", "-o", tmp_path / "pkg",
                                 cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    manifest = json.loads((tmp_path / "pkg" / "chaingen.json").read_text())
    assert manifest["sensitivities"] is False
    assert not manifest["entry_points"]["step_sensitivities"]["available"]
    assert "generated without them" in (tmp_path / "pkg" / "three_link_mono_es.h").read_text()


@pytest.mark.compile
def test_newton_failure_exits_1_and_writes_nothing(tmp_path):
    # A huge stiffness with a 1 s step: Newton's method cannot converge on the first step.
    scene = write_scene(tmp_path, MONO_TEXT.replace("stiffness = 1.0", "stiffness = 1e9"))
    out = tmp_path / "out.csv"
    result = chaingen("simulate", scene, "--dt", "1.0", "--t-end", "5", "--out", out,
                      cwd=tmp_path)
    report = f"exit {result.returncode}\nstdout:\n{result.stdout}\nstderr:\n{result.stderr}"
    assert result.returncode == EXIT_FAILED, report
    assert "Traceback" not in result.stderr, report
    assert re.search(r"\bstep \d+\b", result.stderr), report
    assert "Newton" in result.stderr, report
    assert str(scene) in result.stderr, report
    assert not out.exists()
    assert snapshot(tmp_path) == {"scene.toml"}


# -- file permissions: outputs should be created like any other file (umask) ----------------

def current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@pytest.mark.compile
def test_trajectory_file_permissions_follow_umask(tmp_path):
    if 0o666 & ~current_umask() == 0o600:
        pytest.skip("the umask gives 0600 anyway")
    out = tmp_path / "traj.csv"
    result = chaingen("simulate", GRAVITY, "--t-end", "0.1", "--out", out, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert out.stat().st_mode & 0o777 == 0o666 & ~current_umask()


@pytest.mark.compile
def test_com_at_the_proximal_joint_is_refused_by_es_only(tmp_path):
    scene = write_scene(tmp_path, edited(("com = 0.5", "com = 0.0", 0)))
    out = tmp_path / "out.csv"
    message = error_line(chaingen("simulate", scene, "--out", out, cwd=tmp_path))
    assert_names(message, f"{scene}: links[0].com", "COM")
    assert not out.exists()
    result = chaingen("simulate", scene, "--method", "midpoint", "--t-end", "0.1", cwd=tmp_path)
    assert result.returncode == 0, result.stderr


@pytest.mark.compile
def test_order_prints_the_study_and_writes_the_plot(tmp_path):
    result = chaingen("order", MONO, "--method", "midpoint", "--plot", tmp_path / "order.png",
                      cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "energy order      2.0" in result.stdout and "trajectory order  2.0" in result.stdout
    assert (tmp_path / "order.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_order_with_a_bad_duration_is_bad_input(tmp_path):
    result = chaingen("order", MONO, "--t-end", "0.3", cwd=tmp_path)
    assert result.returncode == 2
    assert "--t-end: must be a whole multiple" in result.stderr and "Traceback" not in result.stderr
