"""The papercuts a new user met (issue 18), each with the check that fails without its fix."""
from __future__ import annotations

import platform
import re
import shutil
import subprocess

import pytest

from chaingen.studies.bench.config import QUICK_MARK, REPORT_TITLE, BenchError, bench_config

from helpers import ROOT, chaingen_in_process


def test_the_readme_first_command_leaves_only_ignored_files():
    """The README's first command writes its trajectory (and metadata) into the checkout:
    git must ignore them."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    first = re.search(r"```sh\n(.*?)\n", (ROOT / "README.md").read_text()).group(1)
    out = re.search(r"--out (\S+)", first).group(1)
    for name in (out, f"{out}.json"):
        result = subprocess.run(["git", "check-ignore", "-q", name], cwd=ROOT)
        assert result.returncode == 0, f"{name} (written by the README's first command) " \
                                       "is not ignored by .gitignore"


def test_quick_bench_does_not_replace_a_full_report(tmp_path):
    full = tmp_path / "benchmarks.md"
    full.write_text(f"{REPORT_TITLE}\n\nWritten by `chaingen bench` in 16 min.\n")
    with pytest.raises(BenchError, match="report of a full run.*give another --out"):
        bench_config(quick=True, out=full)
    assert bench_config(quick=False, out=full).out == full          # a full run may
    quick = tmp_path / "quick.md"
    quick.write_text(f"{REPORT_TITLE}\n\nWritten by `chaingen bench --quick`. {QUICK_MARK}: a "
                     "smoke test.\n")
    assert bench_config(quick=True, out=quick).out == quick         # a quick one it may replace
    other = tmp_path / "notes.md"
    other.write_text("# my notes\n")
    assert bench_config(quick=True, out=other).out == other


def test_quick_bench_refuses_the_committed_report_from_the_command_line(tmp_path):
    before = (ROOT / "docs" / "benchmarks.md").read_bytes()
    result = chaingen_in_process("bench", "--quick", "--out", ROOT / "docs" / "benchmarks.md",
                                 cwd=tmp_path)
    assert result.returncode == 2
    assert "report of a full run" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert (ROOT / "docs" / "benchmarks.md").read_bytes() == before


@pytest.mark.compile
def test_from_directory_loads_a_package_built_in_place_with_make(tmp_path):
    """A package built with its Makefile holds objects and a library beside the sources:
    Solver.from_directory reads only the files its manifest lists."""
    from chaingen import Solver, load_reference_scene

    package = tmp_path / "package"
    assert chaingen_in_process("generate", ROOT / "scenes" / "three_link_mono.toml", "-o",
                               package, "--no-sensitivities", cwd=tmp_path).returncode == 0
    subprocess.run(["make", "-s"], cwd=package, check=True, capture_output=True)
    binaries = [path for path in package.iterdir() if path.suffix in (".o", ".a", ".so")]
    assert binaries, sorted(path.name for path in package.iterdir())
    solver = Solver.from_directory(package)
    scene = load_reference_scene("three_link_mono")
    x0 = solver.initial_state(scene.initial_angles, scene.initial_velocities)
    assert solver.step(x0, dt=0.01).iterations >= 1


@pytest.mark.compile
def test_readme_example_output_is_a_fresh_runs(tmp_path):
    """The README's example block equals a fresh `chaingen simulate` of it in every field that
    does not depend on the machine's speed; the errors exactly on x86-64 (the README's
    machine), to their order of magnitude elsewhere (their last digits move with the machine
    and the compiler)."""
    text = (ROOT / "README.md").read_text()
    block = re.search(r"```\n\$ (chaingen simulate \S+)\n(.*?)```", text, re.S)
    assert block, "no example block in the README"
    command, shown = block.group(1).split(), block.group(2)
    result = chaingen_in_process(*command[1:], cwd=ROOT)
    assert result.returncode == 0, result.stderr
    fresh = result.stdout

    def fields(summary: str) -> dict:
        lines = summary.strip("\n").splitlines()
        found = {"header": lines[0].strip()}
        for line in lines[1:]:                  # "  <label, 23 columns><value>"
            found[line[2:25].strip()] = line[25:].strip()
        return found

    expected, got = fields(shown), fields(fresh)
    assert set(expected) == set(got)
    for name in ("header", "steps", "Newton iterations"):
        assert expected[name] == got[name], name
    for name in ("max |energy error|", "max |constraint error|"):
        if platform.machine() == "x86_64":      # the README's machine: the same bits
            assert expected[name] == got[name], name
            continue
        shown_value, fresh_value = (float(value.split()[0]) for value in (expected[name],
                                                                           got[name]))
        assert fresh_value == 0.0 and shown_value == 0.0 or \
            0.1 <= fresh_value / shown_value <= 10.0, (name, shown_value, fresh_value)
