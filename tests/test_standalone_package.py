"""The checked-in package generated/four_link_actuated_es as a user gets it: built, installed and
consumed with CMake by gcc and clang, its example program run under valgrind and the sanitizers,
two solver instances side by side, and the example's handling of bad arguments.

Every build works on a copy of the package in tmp_path; nothing is built inside generated/.
A missing tool (cmake, clang, valgrind, ...) skips the tests that need it, unless
CHAINGEN_REQUIRE_TOOLS=1 is set (as .ci/run does): then it fails them.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from chaingen.runtime import contract

from helpers import ROOT, require_tools

pytestmark = pytest.mark.tools

PACKAGE = ROOT / "generated" / "four_link_actuated_es"
PREFIX = "four_link_actuated_es"
STRICT = list(contract.STRICT_FLAGS)
SANITIZE = ["-fsanitize=address,undefined", "-fno-omit-frame-pointer",
            "-fno-sanitize-recover=all", "-g"]
COMPILERS = ("gcc", "clang")
# Defined in every shared object by some linkers (older GNU ld), not by the package's sources.
LINKER_SYMBOLS = {"_init", "_fini", "_edata", "_end", "__bss_start"}


def run(command, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([str(part) for part in command], capture_output=True, text=True,
                          timeout=300, **kwargs)


def output(result: subprocess.CompletedProcess) -> str:
    return (f"command: {' '.join(result.args)}\nexit status: {result.returncode}\n"
            f"--- stdout ---\n{result.stdout}\n--- stderr ---\n{result.stderr}")


def check(command, **kwargs) -> subprocess.CompletedProcess:
    """Run a build step and assert it succeeded."""
    result = run(command, **kwargs)
    assert result.returncode == 0, output(result)
    return result


def copy_package(directory: Path) -> Path:
    destination = directory / PREFIX
    shutil.copytree(PACKAGE, destination)
    return destination


def package_sources(package: Path) -> list[Path]:
    sources = json.loads((package / "chaingen.json").read_text())["sources"]
    return [package / name for name in sources]


def compile_example(directory: Path, flags: list[str], name: str) -> Path:
    """The example compiled directly from the package's sources with gcc."""
    package = copy_package(directory)
    binary = directory / name
    check(["gcc", *flags, f"-I{package}", *package_sources(package), package / "example.c",
           "-lm", "-o", binary])
    return binary


def example_results(result: subprocess.CompletedProcess) -> tuple[float, int, int]:
    """The final tracking error, the worst-case Newton iterations and their limit."""
    assert result.returncode == 0, output(result)
    error = re.search(r"^final tracking error (\S+) rad$", result.stdout, re.MULTILINE)
    worst = re.search(r"^worst-case Newton iterations (\d+) \(limit (\d+)\)$", result.stdout,
                      re.MULTILINE)
    assert error and worst, output(result)
    # the same controller closed inside simulate_controlled takes the same steps
    closed = re.search(r"^simulate_controlled: final posture within (\S+) rad of the loop's$",
                       result.stdout, re.MULTILINE)
    assert closed and float(closed.group(1)) == 0.0, output(result)
    return float(error.group(1)), int(worst.group(1)), int(worst.group(2))


# --- CMake: configure, build, install, with gcc and clang, static and shared -------------------

@pytest.fixture(scope="module", params=COMPILERS)
def cmake_builds(request, tmp_path_factory):
    """The package configured, built and installed with one compiler, once as a static and once
    as a shared library (separate build trees and install prefixes)."""
    compiler = request.param
    require_tools("cmake", compiler)
    root = tmp_path_factory.mktemp(f"cmake-{compiler}")
    package = copy_package(root)
    builds = {}
    for linkage, shared in (("static", "OFF"), ("shared", "ON")):
        build, prefix = root / f"build-{linkage}", root / f"install-{linkage}"
        check(["cmake", "-S", package, "-B", build, f"-DCMAKE_C_COMPILER={compiler}",
               f"-DCMAKE_C_FLAGS={' '.join(STRICT)}", "-DCMAKE_BUILD_TYPE=Release",
               f"-DBUILD_SHARED_LIBS={shared}", f"-D{PREFIX.upper()}_BUILD_EXAMPLE=ON",
               f"-DCMAKE_INSTALL_PREFIX={prefix}"])
        check(["cmake", "--build", build, "--parallel"])
        check(["cmake", "--install", build])
        builds[linkage] = {"build": build, "prefix": prefix}
    return {"compiler": compiler, **builds}


@pytest.mark.slow
def test_cmake_installs_header_and_libraries(cmake_builds):
    for linkage, library in (("static", f"lib{PREFIX}.a"), ("shared", f"lib{PREFIX}.so")):
        prefix = cmake_builds[linkage]["prefix"]
        header = prefix / "include" / f"{PREFIX}.h"
        assert header.is_file(), f"{linkage}: no {header}"
        assert header.read_bytes() == (PACKAGE / f"{PREFIX}.h").read_bytes()
        installed = [path for path in prefix.rglob(library) if path.is_file()]
        assert installed, f"{linkage}: no {library} under {prefix}: {sorted(prefix.rglob('*'))}"
        configs = list(prefix.rglob(f"{PREFIX}Config.cmake"))
        assert configs, f"{linkage}: no CMake package configuration under {prefix}"


def test_shared_library_exports_exactly_the_header_api(cmake_builds):
    """Only prefixed symbols, and of those only what the header declares with PREFIX_API."""
    require_tools("nm")
    prefix = cmake_builds["shared"]["prefix"]
    libraries = [path for path in prefix.rglob(f"lib{PREFIX}.so") if path.is_file()]
    assert libraries, f"no shared library under {prefix}"
    result = check(["nm", "-D", "--defined-only", libraries[0]])
    symbols = {line.split()[-1] for line in result.stdout.splitlines() if line.strip()}
    api = set(re.findall(rf"^{PREFIX.upper()}_API\n[\w ]+?\**\s*({PREFIX}_\w+)\(",
                         (PACKAGE / f"{PREFIX}.h").read_text(), flags=re.M))
    assert f"{PREFIX}_step_sensitivities" in api
    assert symbols - LINKER_SYMBOLS == api, output(result)


def test_installed_cmake_files_name_no_build_machine_path(cmake_builds):
    """The install is relocatable: its CMake files link libm by name, not by an absolute path."""
    for linkage in ("static", "shared"):
        for path in cmake_builds[linkage]["prefix"].rglob("*.cmake"):
            text = path.read_text()
            assert "/usr/lib" not in text and "libm.so" not in text, path


@pytest.mark.parametrize("linkage", ["static", "shared"])
def test_cmake_built_example_reaches_the_target(cmake_builds, linkage):
    example = cmake_builds[linkage]["build"] / f"{PREFIX}_example"
    assert example.is_file(), f"example target not built: {example}"
    result = run([example])
    error, worst, limit = example_results(result)
    print(f"{cmake_builds['compiler']} {linkage}: final tracking error {error:.3e} rad, "
          f"worst-case Newton iterations {worst} (limit {limit})")
    assert error < 1e-3, output(result)
    assert 1 <= worst <= limit, output(result)


CONSUMER_CMAKE = f"""\
cmake_minimum_required(VERSION 3.13)
project(consumer C)
find_package({PREFIX} REQUIRED)
add_executable(app main.c)
target_link_libraries(app PRIVATE {PREFIX}::{PREFIX})
"""

CONSUMER_MAIN = f"""\
#include <stdio.h>
#include <{PREFIX}.h>

int main(void)
{{
    static {PREFIX}_workspace workspace;
    {PREFIX}_options options;
    const double phi[{PREFIX.upper()}_N_JOINTS] = {{ 0.785, 0.3, 0.3, -0.2 }};
    const double phidot[{PREFIX.upper()}_N_JOINTS] = {{ 0.0, 0.0, 0.0, 0.0 }};
    double x[{PREFIX.upper()}_NX];
    int status;
    {PREFIX}_default_options(&options);
    status = {PREFIX}_initial_state(phi, phidot, NULL, 0, x, &workspace);
    if (status != {PREFIX.upper()}_OK || options.max_iterations < 1) {{
        printf("FAILED status %d max_iterations %d\\n", status, options.max_iterations);
        return 1;
    }}
    printf("OK\\n");
    return 0;
}}
"""


@pytest.mark.parametrize("linkage", ["static", "shared"])
def test_find_package_consumer_builds_and_runs(cmake_builds, linkage, tmp_path):
    project = tmp_path / "consumer"
    project.mkdir()
    (project / "CMakeLists.txt").write_text(CONSUMER_CMAKE)
    (project / "main.c").write_text(CONSUMER_MAIN)
    build = tmp_path / "build"
    check(["cmake", "-S", project, "-B", build,
           f"-DCMAKE_C_COMPILER={cmake_builds['compiler']}",
           f"-DCMAKE_C_FLAGS={' '.join(STRICT)}",
           f"-DCMAKE_PREFIX_PATH={cmake_builds[linkage]['prefix']}"])
    check(["cmake", "--build", build])
    result = run([build / "app"])
    assert result.returncode == 0 and result.stdout.strip() == "OK", output(result)


# --- The example under valgrind and the sanitizers ---------------------------------------------

def test_example_is_clean_under_valgrind(tmp_path):
    require_tools("gcc", "valgrind")
    example = compile_example(tmp_path, ["-g", "-O1", *STRICT], "example")
    # t_end = 2 s: 2000 steps, about a second under memcheck.
    result = run(["valgrind", "--error-exitcode=99", "--leak-check=full",
                  "--errors-for-leak-kinds=all", example, "2"])
    assert result.returncode == 0, output(result)
    assert "ERROR SUMMARY: 0 errors" in result.stderr, output(result)
    for kind in ("definitely lost", "indirectly lost"):
        lost = re.search(rf"{kind}: ([\d,]+) bytes", result.stderr)
        assert lost is None or lost.group(1) == "0", output(result)
    assert ("All heap blocks were freed" in result.stderr
            or "in use at exit: 0 bytes" in result.stderr), output(result)
    example_results(result)


def valgrind_clean(result: subprocess.CompletedProcess) -> None:
    assert result.returncode == 0, output(result)
    assert "ERROR SUMMARY: 0 errors" in result.stderr, output(result)


@pytest.mark.parametrize("scene", ["three_link_mono", "four_link_actuated"])
@pytest.mark.parametrize("method", ["es", "vi", "midpoint"])
@pytest.mark.slow
def test_every_scheme_example_is_clean_under_valgrind(tmp_path, scene, method):
    """Each scheme's package, unactuated and actuated (with damping), generated afresh: its
    example program under memcheck, no error (no uninitialised workspace field read)."""
    require_tools("gcc", "valgrind")
    from chaingen.generate.package import generate_package, write_package

    from helpers import load

    package = write_package(generate_package(load(scene), method, 3), tmp_path / "package")
    sources = json.loads((package / "chaingen.json").read_text())["sources"]
    example = tmp_path / "example"
    check(["gcc", "-g", "-O1", *STRICT, f"-I{package}", *(package / name for name in sources),
           package / "example.c", "-lm", "-o", example])
    valgrind_clean(run(["valgrind", "--error-exitcode=99", "--track-origins=yes", example,
                        "0.5"]))


@pytest.mark.parametrize("method, order", [("es", 4), ("es", 6), ("vi", 6), ("midpoint", 6)])
@pytest.mark.slow
def test_composed_examples_are_clean_under_valgrind_and_the_sanitizers(tmp_path, method, order):
    """A composed step (docs/model.md 14), actuated with damping: with the strict flags, the
    example program (its stages) and a call of the chained step sensitivities (es: chained in
    the whole state, then mapped to joint space) run clean under memcheck and ASan/UBSan."""
    require_tools("gcc", "valgrind")
    from chaingen.generate.package import generate_package, write_package

    from helpers import load

    package = write_package(generate_package(load("four_link_actuated"), method, 3,
                                             order=order, sensitivities=True),
                            tmp_path / "package")
    manifest = json.loads((package / "chaingen.json").read_text())
    prefix, sources = manifest["prefix"], manifest["sources"]
    programs = {"example.c": ["0.5"]}
    if manifest["sensitivities"]:
        (package / "sensitivities.c").write_text(f"""#include "{prefix}.h"
int main(void)
{{
    static {prefix}_workspace ws;
    double phi[4] = {{0.3, -0.2, 0.1, 0.4}}, phidot[4] = {{0.5, 0.0, -0.3, 0.2}};
    double u[{prefix.upper()}_NU] = {{0.0}}, x[{prefix.upper()}_NX], x1[{prefix.upper()}_NX];
    double ds_ds[64], ds_du[8 * {prefix.upper()}_NU];
    int iterations, status;
    {prefix}_workspace_init(&ws);
    status = {prefix}_initial_state(phi, phidot, NULL, 0, x, &ws);
    if (status == 0) {{
        status = {prefix}_step_sensitivities(x, u, {prefix.upper()}_NU, NULL, 0, 0.01, x1, ds_ds,
                                              ds_du, NULL, NULL, &ws, &iterations);
    }}
    return status;
}}
""")
        programs["sensitivities.c"] = []
    for program, arguments in programs.items():
        for name, flags, runner in (("memcheck", ["-g", "-O1"],
                                     ["valgrind", "--error-exitcode=99", "--track-origins=yes"]),
                                    ("sanitized", SANITIZE, [])):
            binary = tmp_path / f"{program}.{name}"
            check(["gcc", *flags, *STRICT, f"-I{package}", *(package / s for s in sources),
                   package / program, "-lm", "-o", binary])
            result = run([*runner, binary, *arguments])
            if runner:
                valgrind_clean(result)
            else:
                assert result.returncode == 0, output(result)


def test_example_is_clean_under_address_and_undefined_sanitizers(tmp_path):
    require_tools("gcc")
    example = compile_example(tmp_path, [*SANITIZE, *STRICT], "example")
    environment = dict(os.environ)
    # LeakSanitizer works in this environment (checked: it reports a deliberate leak), so leaks
    # are checked too. Where it cannot run (e.g. under ptrace) set detect_leaks=0 here.
    environment["ASAN_OPTIONS"] = "detect_leaks=1:abort_on_error=0"
    environment["UBSAN_OPTIONS"] = "print_stacktrace=1:halt_on_error=1"
    result = run([example, "2"], env=environment)
    assert result.returncode == 0, output(result)
    for report in ("runtime error", "ERROR: AddressSanitizer", "ERROR: LeakSanitizer",
                   "SUMMARY: "):
        assert report not in result.stderr, output(result)
    example_results(result)


# --- Two solver instances side by side -----------------------------------------------------------

SIDE_BY_SIDE = f"""\
#include <stdio.h>
#include <string.h>
#include "{PREFIX}.h"

#define NJ {PREFIX.upper()}_N_JOINTS
#define NX {PREFIX.upper()}_NX
#define NU {PREFIX.upper()}_NU
#define STEPS 200

static const double dt = 0.001;
static const double phi0[2][NJ] = {{ {{ 0.785, 0.3, 0.3, -0.2 }}, {{ -0.4, 0.6, -0.5, 0.25 }} }};
static const double phidot0[2][NJ] = {{ {{ 0.0, 0.0, 0.0, 0.0 }}, {{ 0.5, -1.0, 0.3, 2.0 }} }};
static const double torque[2][NU] = {{ {{ 1.5, -0.5, 0.2, 0.05 }}, {{ -2.0, 0.7, -0.1, 0.02 }} }};

/* Run instance i alone for STEPS steps from its initial state, with a workspace of its own. */
static int alone(int i, double *x, {PREFIX}_workspace *workspace)
{{
    double next[NX];
    int k, status = {PREFIX}_initial_state(phi0[i], phidot0[i], NULL, 0, x, workspace);
    for (k = 0; k < STEPS && status == {PREFIX.upper()}_OK; ++k) {{
        status = {PREFIX}_step(x, torque[i], {PREFIX.upper()}_NU, NULL, 0, dt, next, NULL, NULL,
                               workspace, NULL);
        memcpy(x, next, sizeof next);
    }}
    return status;
}}

int main(void)
{{
    /* The side-by-side workspaces start with garbage and are initialised, the lone ones are
     * zeroed: the results may not depend on what a workspace held before. */
    static {PREFIX}_workspace together[2], single[2];
    double x[2][NX], next[2][NX], x_alone[2][NX], flows[2][2];
    int i, k, status = {PREFIX.upper()}_OK, iterations[2] = {{ 0, 0 }};
    memset(together, 0xA5, sizeof together);
    {PREFIX}_workspace_init(&together[0]);
    {PREFIX}_workspace_init(&together[1]);
    memset(single, 0, sizeof single);
    for (i = 0; i < 2 && status == {PREFIX.upper()}_OK; ++i) {{
        status = {PREFIX}_initial_state(phi0[i], phidot0[i], NULL, 0, x[i], &together[i]);
    }}
    for (k = 0; k < STEPS && status == {PREFIX.upper()}_OK; ++k) {{
        for (i = 0; i < 2 && status == {PREFIX.upper()}_OK; ++i) {{
            status = {PREFIX}_step(x[i], torque[i], {PREFIX.upper()}_NU, NULL, 0, dt, next[i],
                                   flows[i], NULL, &together[i],
                                   &iterations[i]);
            memcpy(x[i], next[i], sizeof next[i]);
        }}
    }}
    if (status != {PREFIX.upper()}_OK) {{
        printf("FAILED side by side: status %d at step %d\\n", status, k);
        return 1;
    }}
    for (i = 0; i < 2; ++i) {{
        status = alone(i, x_alone[i], &single[i]);
        if (status != {PREFIX.upper()}_OK) {{
            printf("FAILED alone %d: status %d\\n", i, status);
            return 1;
        }}
        if (memcmp(x[i], x_alone[i], sizeof x[i]) != 0) {{
            printf("MISMATCH instance %d\\n", i);
            return 1;
        }}
    }}
    if (memcmp(x[0], x[1], sizeof x[0]) == 0) {{
        printf("FAILED: the two instances ended in the same state\\n");
        return 1;
    }}
    printf("OK %.17g %.17g\\n", x[0][0], x[1][0]);
    return 0;
}}
"""


def test_two_workspaces_side_by_side_match_lone_runs_bitwise(tmp_path):
    require_tools("gcc")
    package = copy_package(tmp_path)
    program = tmp_path / "side_by_side.c"
    program.write_text(SIDE_BY_SIDE)
    binary = tmp_path / "side_by_side"
    check(["gcc", "-O2", *STRICT, f"-I{package}", program, *package_sources(package), "-lm",
           "-o", binary])
    result = run([binary])
    assert result.returncode == 0 and result.stdout.startswith("OK "), output(result)


# --- The example's arguments ---------------------------------------------------------------------

@pytest.fixture(scope="module")
def plain_example(tmp_path_factory):
    require_tools("gcc")
    return compile_example(tmp_path_factory.mktemp("example"), ["-O2", *STRICT], "example")


@pytest.mark.parametrize("arguments", [
    ["abc"], ["-1"], ["0"], ["nan"], ["inf"], ["1e999"], ["1.5x"], [""],
    ["1", "0", "0"],                    # too few target angles
    ["1", "0", "0", "0", "0", "0"],     # too many
    ["1", "0", "0", "zero", "0"],       # a target angle that is no number
    ["1", "0", "0", "0", "inf"],
])
def test_example_rejects_bad_arguments_with_status_2(plain_example, arguments):
    result = run([plain_example, *arguments])
    assert result.returncode == 2, output(result)
    assert result.stderr.strip(), output(result)
    assert "final tracking error" not in result.stdout, output(result)


@pytest.mark.parametrize("arguments", [[], ["0.5"], ["0.5", "1.0", "0.1", "-0.1", "0"]])
def test_example_accepts_good_arguments(plain_example, arguments):
    result = run([plain_example, *arguments])
    error, worst, limit = example_results(result)
    assert 1 <= worst <= limit, output(result)


@pytest.mark.parametrize("method, order", [("es", 2), ("es", 4), ("es", 6), ("vi", 2),
                                           ("midpoint", 4)])
@pytest.mark.slow
def test_adaptive_runs_are_clean_under_valgrind_and_the_sanitizers(tmp_path, method, order):
    """simulate with adaptive steps (rtol, atol) on an actuated, damped scene: with the strict
    flags the run completes, refuses at least one step (a first try at the whole interval), and
    is clean under memcheck and ASan/UBSan."""
    require_tools("gcc", "valgrind")
    from chaingen.generate.package import generate_package, write_package

    from helpers import load

    package = write_package(generate_package(load("four_link_actuated"), method, 3,
                                             order=order, sensitivities=False),
                            tmp_path / "package")
    manifest = json.loads((package / "chaingen.json").read_text())
    prefix, sources = manifest["prefix"], manifest["sources"]
    P = prefix.upper()
    (package / "adaptive.c").write_text(f"""#include <stdio.h>
#include "{prefix}.h"
#define STEPS 20
int main(void)
{{
    static {prefix}_workspace ws;
    static double samples[(STEPS + 1) * {P}_NSAMPLE];
    double phi[4] = {{0.3, -0.2, 0.1, 0.4}}, phidot[4] = {{0.5, 0.0, -0.3, 0.2}};
    double u[STEPS * {P}_NU] = {{0.0}}, x[{P}_NX];
    {prefix}_options options;
    {prefix}_stats stats;
    int status;
    {prefix}_default_options(&options);
    options.rtol = 1e-8;
    options.atol = 1e-8;
    {prefix}_workspace_init(&ws);
    status = {prefix}_initial_state(phi, phidot, NULL, 0, x, &ws);
    if (status == {P}_OK) {{
        status = {prefix}_simulate(x, 0.0, 0.1, STEPS, 1, u, {P}_NU, NULL, 0, &options, &ws,
                                   samples, NULL, &stats);
    }}
    printf("%d %ld %ld %ld %g %g\\n", status, stats.steps, stats.accepted_steps,
           stats.rejected_steps, stats.smallest_dt, stats.largest_dt);
    options.rtol = 1e-20;   /* below the floor: refused */
    if (status == {P}_OK && {prefix}_simulate(x, 0.0, 0.1, STEPS, 1, u, {P}_NU, NULL, 0, &options,
                                              &ws, samples, NULL, &stats) != {P}_BAD_ARGUMENT) {{
        return 98;
    }}
    return status;
}}
""")
    for name, flags, runner in (("memcheck", ["-g", "-O1"],
                                 ["valgrind", "--error-exitcode=99", "--track-origins=yes"]),
                                ("sanitized", SANITIZE, [])):
        binary = tmp_path / f"adaptive.{name}"
        check(["gcc", *flags, *STRICT, f"-I{package}", *(package / s for s in sources),
               package / "adaptive.c", "-lm", "-o", binary])
        result = run([*runner, binary])
        if runner:
            valgrind_clean(result)
        else:
            assert result.returncode == 0, output(result)
        status, steps, accepted, rejected, smallest, largest = result.stdout.split()
        assert (int(status), int(steps)) == (0, 20)
        assert int(accepted) >= 40 and int(rejected) >= 1
        assert 0 < float(smallest) <= float(largest) <= 0.05


def test_readme_quotes_the_examples_figures(plain_example):
    """The README's sentence on the example: its final tracking error (as printed, to two
    digits) and its worst-case Newton count."""
    error, worst, _ = example_results(run([plain_example]))
    quoted = re.search(r"ends with a tracking error of (\S+) rad, at\s+most (\d+) Newton",
                       (ROOT / "README.md").read_text())
    assert quoted, "README.md no longer describes the example's run"
    assert (quoted.group(1), int(quoted.group(2))) == (f"{error:.1e}".replace("e-0", "e-"), worst)
