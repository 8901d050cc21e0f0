"""The README's set-up needs what the README names (Python 3.11+ and a C compiler): the `test`
extra installs no compiled peer (numbalsoda has no wheel and builds from source with gfortran
and a C++ compiler), the tests of the peers skip without them and name the extra, and CI
(.ci/run) installs them and requires them (CHAINGEN_REQUIRE_TOOLS=1)."""
from __future__ import annotations

import os
import re
import subprocess
import sys
import tomllib

import pytest
import test_compiled_peers

from helpers import ROOT

#: The compiled peers: numbalsoda (no wheel: built from source with gfortran) and numba.
PEER_PACKAGES = {"numbalsoda", "numba"}


def extras() -> dict[str, list[str]]:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]


def requirement_names(extra: str, seen: frozenset = frozenset()) -> set[str]:
    """The distributions an extra installs, through its chaingen[...] self-references."""
    names = set()
    for requirement in extras()[extra]:
        name, _, rest = re.match(r"([A-Za-z0-9_.-]+)(\[([^\]]*)\])?", requirement).groups()
        if name.lower() == "chaingen":
            for inner in rest.split(","):
                if inner.strip() not in seen:
                    names |= requirement_names(inner.strip(), seen | {extra})
        else:
            names.add(name.lower())
    return names


def test_the_test_extra_installs_no_compiled_peer():
    """pip install -e '.[test]' (the README's first command) must not build numbalsoda."""
    assert requirement_names("test") & PEER_PACKAGES == set()
    assert requirement_names("peers") == PEER_PACKAGES            # the peers stay an extra
    assert {"pytest", "pytest-xdist", "hypothesis", "ruff", "pyarrow"} <= requirement_names("test")


def test_ci_installs_and_requires_the_peers():
    """CI installs the compiled peers and the robots extra (Pinocchio and example-robot-data,
    whose tests fail there rather than skip)."""
    ci = (ROOT / ".ci" / "run").read_text()
    assert "pip install --quiet -e '.[test,peers,robots]'" in ci
    assert "export CHAINGEN_REQUIRE_TOOLS=1" in ci
    assert re.search(r"apt-get install [^\n]*gfortran", ci)


def test_the_readme_names_what_the_set_up_needs():
    readme = (ROOT / "README.md").read_text()
    assert readme.split("```sh\n", 1)[1].startswith(
        "pip install -e '.[test]' && chaingen simulate")
    assert "Both need Python 3.11+ and a C compiler" in readme
    assert "pip install -e '.[test,peers]'" in readme and "gfortran" in readme


@pytest.mark.heavy
def test_compiled_peer_tests_skip_without_numbalsoda(tmp_path):
    """With numbalsoda and numba missing (modules that refuse to import, first on the path),
    every test of a numbalsoda method skips naming the extra, before anything is built (CC
    points at no compiler here); the core and bench modules import without them."""
    for name in PEER_PACKAGES:
        (tmp_path / f"{name}.py").write_text(
            f"raise ImportError('{name} hidden by test_setup', name='{name}')\n")
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join(
        filter(None, [str(tmp_path), os.environ.get("PYTHONPATH")]))}
    environment.pop("CHAINGEN_REQUIRE_TOOLS", None)
    result = subprocess.run(
        [sys.executable, "-m", "pytest", "-o", "addopts=", "-p", "no:xdist", "-p",
         "no:cacheprovider", f"--basetemp={tmp_path / 'pytest'}", "-q", "-rs", "-m",
         "compile", "-k", "numbalsoda", "tests/test_compiled_peers.py"],
        capture_output=True, text=True, cwd=ROOT, env=environment, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    assert re.search(r"\b8 skipped\b", result.stdout), result.stdout
    assert "passed" not in result.stdout and "error" not in result.stdout.lower()
    assert re.search(r"SKIPPED \[8\] .*numbalsoda is not installed \(the `peers` extra",
                     result.stdout), result.stdout

    code = ("import sys\n"
            "import chaingen, chaingen.cli, chaingen.simulation, chaingen.studies.bench.runs\n"
            "from chaingen.reference import compiled_peers\n"
            "assert not compiled_peers.numbalsoda_available()\n"
            "print(sorted(m for m in ('numba', 'numbalsoda') if m in sys.modules))\n")
    imported = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              cwd=ROOT, env=environment, timeout=120)
    assert imported.returncode == 0, imported.stderr
    assert imported.stdout.strip() == "[]"


@pytest.mark.parametrize("required, outcome", [(None, pytest.skip.Exception),
                                               ("1", pytest.fail.Exception)])
def test_a_missing_peer_fails_where_required(required, outcome, monkeypatch):
    """CHAINGEN_REQUIRE_TOOLS=1 (.ci/run) turns the skip into a failure naming the extra."""
    monkeypatch.setitem(sys.modules, "numbalsoda", None)
    if required is None:
        monkeypatch.delenv("CHAINGEN_REQUIRE_TOOLS", raising=False)
    else:
        monkeypatch.setenv("CHAINGEN_REQUIRE_TOOLS", required)
    with pytest.raises(outcome, match=r"numbalsoda is not installed.*\[peers\]"):
        test_compiled_peers.require_peer("numbalsoda-DOP853")
    test_compiled_peers.require_peer("CVODES-BDF")          # CasADi's: never skipped



def test_the_bench_report_says_the_peers_were_not_run(monkeypatch):
    """chaingen bench without the extra: its machine section says which peers did not run and
    why (the runs' rows are notes: test_compiled_peers.test_bench_notes_a_missing_numbalsoda)."""
    import importlib.metadata

    from chaingen.studies.bench.report import machine_description

    installed = dict(machine_description())["compiled peers"]
    version = importlib.metadata.version

    def without_peers(package):
        if package in PEER_PACKAGES:
            raise importlib.metadata.PackageNotFoundError(package)
        return version(package)

    monkeypatch.setattr(importlib.metadata, "version", without_peers)
    missing = dict(machine_description())["compiled peers"]
    assert missing.startswith("numbalsoda's LSODA and DOP853 not run (numbalsoda and numba, "
                              "the `peers` extra, are not installed), CVODES of CasADi ")
    assert "not installed" not in installed or installed == missing


def test_no_install_hint_names_a_package_index():
    """chaingen is installed from its source tree: no message or page may tell a user to
    install it (or an extra of it) from a package index, where it is not published."""
    from chaingen.errors import install_hint

    assert install_hint("sweep") == "in the chaingen source tree: pip install -e '.[sweep]'"
    from_index = re.compile(r"pip install\s+(?:-\S+\s+)*['\"]?chaingen(?:\[|['\"\s]|$)")
    offenders = []
    for path in [ROOT / "README.md", *(ROOT / "docs").rglob("*.md"),
                 *(ROOT / "codegen").rglob("*.py"), *(ROOT / "runtime").rglob("*.py")]:
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if from_index.search(line):
                offenders.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not offenders, "\n".join(offenders)
