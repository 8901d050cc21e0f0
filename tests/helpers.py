"""What the tests share: scene paths, scenes loaded once, solvers built once per session, and
the `chaingen` command run as a user runs it."""
from __future__ import annotations

import contextlib
import io
import os
import shutil
import subprocess
import sys
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
REFERENCE_SCENES = ("three_link_gravity", "three_link_mono", "three_link_multi")
OWN_SCENES = ("four_link_antagonist", "five_link_biarticular")


def scene_path(name: str) -> Path:
    """A reference scene (scenes/) or one of the test suite's own (tests/scenes/)."""
    for folder in (ROOT / "scenes", ROOT / "tests" / "scenes"):
        path = folder / f"{name}.toml"
        if path.exists():
            return path
    raise FileNotFoundError(name)


@cache
def load(name: str):
    from chaingen.scene import load_scene
    return load_scene(scene_path(name))


_solvers: dict = {}


def solver_for(name: str, method: str = "es", quadrature: int = 3, *,
               sensitivities: bool = False, gradient: str = "exact"):
    """The built solver of a scene, generated and compiled once per session.

    Without step sensitivities unless asked: they are the largest generated functions, and
    most tests only step forward. gradient: es's discrete gradient of the springs ("quadrature":
    the thesis's K-point average alone).
    """
    key = (name, method, quadrature, sensitivities, gradient)
    if key not in _solvers:
        from chaingen.simulation import build_solver
        _solvers[key] = build_solver(load(name), method, quadrature, sensitivities=sensitivities,
                                     gradient=gradient)
    return _solvers[key]


def chaingen(*args, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run `python -m chaingen ARGS` in `cwd` (so a default output directory lands there)."""
    return subprocess.run([sys.executable, "-m", "chaingen", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=timeout)


def chaingen_in_process(*args, cwd: Path) -> subprocess.CompletedProcess:
    """`chaingen ARGS` as chaingen.cli.main runs it, in this process (for the many bad-input
    cases, where a process per case would dominate the fast tier): its exit status and what
    it printed. An exception main lets through propagates (a traceback a user would see)."""
    from chaingen.cli import main

    arguments = [str(arg) for arg in args]
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.chdir(cwd), contextlib.redirect_stdout(stdout), \
            contextlib.redirect_stderr(stderr):
        try:
            status = main(arguments)
        except SystemExit as exit_:     # argparse's own errors
            status = exit_.code
    return subprocess.CompletedProcess(["chaingen", *arguments], status, stdout.getvalue(),
                                       stderr.getvalue())


def require_tools(*tools: str) -> None:
    """Skip the calling test when a tool is not on PATH; fail instead when
    CHAINGEN_REQUIRE_TOOLS=1 (as .ci/run sets it), so CI cannot pass by skipping."""
    missing = [tool for tool in tools if shutil.which(tool) is None]
    if not missing:
        return
    message = f"required tool(s) not installed: {', '.join(missing)}"
    if os.environ.get("CHAINGEN_REQUIRE_TOOLS") == "1":
        pytest.fail(f"{message} (CHAINGEN_REQUIRE_TOOLS=1)", pytrace=False)
    pytest.skip(message)


def require_module(module: str, extra: str):
    """The imported module, or skip the calling test where it is missing; fail instead when
    CHAINGEN_REQUIRE_TOOLS=1 (as .ci/run sets it, installing the extra), so CI cannot pass by
    skipping."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        message = f"{module} is not installed (the `{extra}` extra: pip install -e '.[{extra}]')"
        if os.environ.get("CHAINGEN_REQUIRE_TOOLS") == "1":
            pytest.fail(f"{message} (CHAINGEN_REQUIRE_TOOLS=1)", pytrace=False)
        pytest.skip(message)


def passed_check(scene, method: str, order: int = 2):
    """chaingen check's comparisons on `scene` with `method` at `order` (3 samples, dt =
    0.01 s): the residual Jacobian and the step sensitivities against central differences,
    every generated function against the scheme's SymPy expressions. Asserts that every one
    of them ran and passed; returns the built solver."""
    from chaingen.simulation import build_solver
    from chaingen.studies.check import check_solver
    from chaingen.symbolic.schemes import build_scheme

    scheme = build_scheme(scene, method, order=order)
    solver = build_solver(scene, method, sensitivities=True, order=order)
    report = check_solver(scheme, solver, samples=3, dt=0.01)
    assert {row.quantity for row in report.rows} >= {
        "residual Jacobian", "d s1 / d s0", "d s1 / d u", "residual", "next state", "energy"}
    assert report.passed, report.table()
    return solver


def run_example_checked(package: Path, work: Path, seconds: str) -> list[str]:
    """The example program of a written package (its directory), compiled with the strict
    flags for memcheck and for ASan/UBSan, run for `seconds` under each: asserts that both
    build and run clean, and returns their standard outputs."""
    import json

    from chaingen.runtime import contract

    sources = [package / name for name in json.loads((package / "chaingen.json").read_text())
               ["sources"]]
    outputs = []
    for name, flags, runner in (
            ("memcheck", ["-g", "-O1"], ["valgrind", "--error-exitcode=99",
                                         "--track-origins=yes", "--leak-check=full"]),
            ("sanitized", ["-g", "-fsanitize=address,undefined", "-fno-omit-frame-pointer",
                           "-fno-sanitize-recover=all"], [])):
        binary = work / name
        built = subprocess.run(["gcc", *flags, *contract.STRICT_FLAGS, f"-I{package}",
                                *map(str, sources), str(package / "example.c"), "-lm", "-o",
                                str(binary)], capture_output=True, text=True, timeout=300)
        assert built.returncode == 0, built.stderr
        run = subprocess.run([*runner, str(binary), seconds], capture_output=True, text=True,
                             timeout=600)
        assert run.returncode == 0, run.stdout + run.stderr
        if runner:
            assert "ERROR SUMMARY: 0 errors" in run.stderr, run.stderr
        outputs.append(run.stdout)
    return outputs
