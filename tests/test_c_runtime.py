"""The C runtime's own test suite (runtime/c/tests), without SymPy or CasADi.

runtime/c/tests/pendulum_model.c is a hand-written model (a pendulum with a spring, gravity, an
actuated damped joint and the spring's stiffness as a parameter, stepped by the implicit
midpoint rule) that fills a chaingen_model, with variants for every feature and knobs that
provoke every failure status; runtime/c/tests/test_runtime.c drives every entry point of
runtime/c/chaingen_runtime.c with it and prints "ok <group>" or "FAIL <group>: detail" per
group. Here the driver is built with the strict flags and run (compile tier), then run under
valgrind's memcheck and under ASan/UBSan with gcc and clang (tools tier). The unity build a
package makes (CHAINGEN_LINKAGE static, the source included) must compile without a warning.

By hand: `make -C runtime/c/tests check` (and `valgrind`, `sanitize`; see its Makefile).
"""
from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import pytest

from chaingen.runtime.build import STRICT_FLAGS, compiler

from helpers import ROOT, require_tools

RUNTIME = ROOT / "runtime" / "c"
TESTS = RUNTIME / "tests"
SUITE = [TESTS / "test_runtime.c", TESTS / "pendulum_model.c", RUNTIME / "chaingen_runtime.c"]
UNITY = [TESTS / "unity_build.c", TESTS / "pendulum_model.c"]
SANITIZE = ["-fsanitize=address,undefined", "-fno-omit-frame-pointer",
            "-fno-sanitize-recover=all", "-g", "-O1"]
# Valgrind and the sanitizers check every access against the workspace's exact size: no guard
# entries after it (test_runtime.c, TEST_GUARD).
EXACT = ["-DTEST_GUARD=0"]
COMPILERS = ("gcc", "clang")


def groups() -> list[str]:
    """The test groups of the driver, from its table (and the final every_status)."""
    source = (TESTS / "test_runtime.c").read_text()
    table = source[source.index("static const test_group groups[]"):]
    return re.findall(r'\{"(\w+)", test_\w+\}', table) + ["every_status"]


def run(command, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([str(part) for part in command], capture_output=True, text=True,
                          timeout=600, **kwargs)


def output(result: subprocess.CompletedProcess) -> str:
    return f"exit {result.returncode}\n{result.stdout[-6000:]}\n{result.stderr[-6000:]}"


def build(tmp_path: Path, cc: str, flags, sources=SUITE, name: str = "test_runtime") -> Path:
    binary = tmp_path / name
    result = run([cc, *STRICT_FLAGS, *flags, f"-I{RUNTIME}", *sources, "-lm", "-o", binary])
    assert result.returncode == 0, output(result)
    assert result.stderr.strip() == "", output(result)   # no warning either
    return binary


def assert_passed(result: subprocess.CompletedProcess) -> None:
    """Exit 0, no FAIL line, and an ok line for every group."""
    assert result.returncode == 0, output(result)
    assert "FAIL" not in result.stdout, output(result)
    passed = set(re.findall(r"^ok (\w+)$", result.stdout, re.MULTILINE))
    missing = [name for name in groups() if name not in passed]
    assert missing == [], f"groups without an ok line: {missing}\n{output(result)}"


@pytest.mark.compile
def test_the_runtime_passes_its_own_suite(tmp_path):
    assert_passed(run([build(tmp_path, compiler(), ["-O2"])]))


def test_the_suite_covers_every_status_code():
    """every_status fails unless some call produced each status 0..11; here, that the contract
    still has exactly those."""
    contract = (RUNTIME / "chaingen_contract.h").read_text()
    codes = {int(value) for value in re.findall(
        r"#define CHAINGEN_(?:OK|NOT_CONVERGED|SINGULAR_JACOBIAN|NONFINITE|BAD_ARGUMENT|"
        r"EVALUATION_FAILED|SEGMENT_COLLAPSED|INTERRUPTED|STEP_TOO_SMALL|ENERGY_JUMP|"
        r"BAD_PARAMETER|UNAVAILABLE) (\d+)", contract)}
    assert codes == set(range(12))
    assert "CHAINGEN_UNAVAILABLE + 1" in (TESTS / "test_runtime.c").read_text()


@pytest.mark.compile
def test_the_unity_build_compiles_without_a_warning_and_runs(tmp_path):
    """CHAINGEN_LINKAGE static and the runtime's source included, as a package does: every
    public function is called, so an unused static function would be a -Werror failure."""
    result = run([build(tmp_path, compiler(), ["-O2"], UNITY, "unity_build")])
    assert result.returncode == 0 and result.stdout.strip() == "ok unity_build", output(result)


@pytest.mark.tools
def test_the_suite_is_clean_under_valgrind(tmp_path):
    require_tools("gcc", "valgrind")
    binary = build(tmp_path, "gcc", ["-g", "-O1", *EXACT])
    result = run(["valgrind", "--error-exitcode=1", "--leak-check=full",
                  "--errors-for-leak-kinds=all", binary])
    assert_passed(result)
    assert "ERROR SUMMARY: 0 errors" in result.stderr, output(result)


@pytest.mark.tools
@pytest.mark.parametrize("cc", COMPILERS)
@pytest.mark.slow
def test_the_suite_is_clean_under_the_sanitizers(tmp_path, cc):
    require_tools(cc)
    binary = build(tmp_path, cc, [*SANITIZE, *EXACT])
    environment = dict(os.environ, UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1",
                       ASAN_OPTIONS="detect_leaks=1:abort_on_error=0")
    result = run([binary], env=environment)
    assert_passed(result)
    assert "runtime error" not in result.stderr and "Sanitizer" not in result.stderr, \
        output(result)


@pytest.mark.tools
def test_the_suite_and_the_unity_build_pass_under_clang(tmp_path):
    require_tools("clang")
    assert_passed(run([build(tmp_path, "clang", ["-O2"])]))
    result = run([build(tmp_path, "clang", ["-O2"], UNITY, "unity_build")])
    assert result.returncode == 0 and result.stdout.strip() == "ok unity_build", output(result)
