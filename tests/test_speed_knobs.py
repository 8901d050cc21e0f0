"""The build and Newton defaults chosen for speed, and the knob study's plumbing.

What the knobs cost and gain is measured by `chaingen bench` (docs/benchmarks.md), never here;
these tests check that each knob does what it says: the per-source compiler flags reach the
compiler in every build path, the large-model rule switches at its threshold, and the per-scheme
Newton defaults are the documented ones.
"""
from __future__ import annotations

import json
import re
import subprocess

import pytest

import chaingen.generate.package as package_module
from chaingen.generate.package import generate_package, write_package
from chaingen.runtime import (
    JACOBIAN_ACROSS_STEPS,
    JACOBIAN_CHORD_ACROSS_STEPS,
    JACOBIAN_PER_STEP,
    NewtonOptions,
    Solver,
)
from chaingen.studies.bench.knobs import KnobRow, knob_table, with_source_flags

from helpers import load


def test_solver_source_is_compiled_with_o3_everywhere():
    package = generate_package(load("three_link_mono"), "es", 3, sensitivities=False)
    prefix = package.prefix
    assert package.manifest["source_flags"] == {f"{prefix}.c": ["-O3"]}
    assert f"{prefix}.o: {prefix}.c\n\t$(CC) $(CFLAGS) -O3 " in package.files["Makefile"]
    # CMake: -O3 where the build optimises (no build type, Release, RelWithDebInfo); the tools
    # tier builds each build type and reads the flags (test_standalone_package).
    assert (f'set_source_files_properties({prefix}.c PROPERTIES COMPILE_OPTIONS\n'
            f'    "$<${{{prefix}_tuned}}:-O3>")' in package.files["CMakeLists.txt"])


@pytest.mark.compile
def test_a_large_model_is_compiled_with_o1(monkeypatch, tmp_path):
    """Above LARGE_MODEL_BYTES the model gets -O1 in the manifest, the Makefile and CMake, and
    chaingen's own build uses it (the compiler command is in the build log on failure: here
    the build must simply succeed and the solver step)."""
    scene = load("three_link_gravity")
    small = generate_package(scene, "midpoint", 3, sensitivities=False)
    model = f"{small.prefix}_model.c"
    assert model not in small.manifest["source_flags"]
    monkeypatch.setattr(package_module, "LARGE_MODEL_BYTES", len(small.files[model]) // 2)
    large = generate_package(scene, "midpoint", 3, sensitivities=False)
    assert large.manifest["source_flags"][model] == ["-O1"]
    assert f"{small.prefix}_model.o: {model}\n\t$(CC) $(CFLAGS) -O1 " in large.files["Makefile"]
    assert (f'set_source_files_properties({model} PROPERTIES COMPILE_OPTIONS\n'
            f'    "$<${{{small.prefix}_tuned}}:-O1>")' in large.files["CMakeLists.txt"])
    solver = Solver.from_files(large.files)
    x0 = solver.initial_state(scene.initial_angles, scene.initial_velocities)
    assert solver.step(x0, dt=0.01).iterations >= 1
    # The Makefile builds with the per-file rules (make -n prints the commands it would run).
    directory = write_package(large, tmp_path / "package")
    commands = subprocess.run(["make", "-n", f"{small.prefix}_model.o", f"{small.prefix}.o"],
                              cwd=directory, capture_output=True, text=True, check=True).stdout
    assert "-O1" in commands and "-O3" in commands


@pytest.mark.compile
@pytest.mark.parametrize("method, reuse", [("es", JACOBIAN_CHORD_ACROSS_STEPS),
                                           ("vi", JACOBIAN_ACROSS_STEPS),
                                           ("midpoint", JACOBIAN_PER_STEP)])
def test_newton_defaults_per_scheme(method, reuse):
    package = generate_package(load("three_link_mono"), method, 3, sensitivities=False)
    defaults = package.manifest["newton_defaults"]
    assert defaults["warm_start"] == 1 and defaults["reuse_jacobian"] == reuse
    header = package.files[f"{package.prefix}.h"]
    defaults_text = " ".join(re.search(r"defaults of this package:(.*?)\*/", header,
                                       re.S).group(1).replace("*", " ").split())
    assert f"reuse_jacobian {reuse}," in defaults_text
    assert f"#define {package.prefix.upper()}_JACOBIAN_PER_STEP {JACOBIAN_PER_STEP} " in header
    solver = Solver.from_files(package.files)
    assert solver.default_options.reuse_jacobian == reuse
    assert json.loads(package.files["chaingen.json"])["newton_defaults"] == defaults


@pytest.mark.compile
def test_knob_options_start_from_the_package_defaults():
    solver = Solver.from_files(generate_package(load("three_link_mono"), "vi", 3,
                                                sensitivities=False).files)
    assert solver.newton_options({}) == solver.default_options
    options = solver.newton_options({"warm_start": 0, "update_rtol": 1e-6})
    assert options == NewtonOptions(warm_start=False, reuse_jacobian=JACOBIAN_ACROSS_STEPS,
                                    update_rtol=1e-6)
    with pytest.raises(ValueError, match="no Newton option unknown"):
        solver.newton_options({"unknown": 1})


def test_with_source_flags_changes_one_source_only():
    package = generate_package(load("three_link_mono"), "es", 3, sensitivities=False)
    changed = with_source_flags(package, f"{package.prefix}.c", ("-O2",))
    assert changed.manifest["source_flags"] == {f"{package.prefix}.c": ["-O2"]}
    assert package.manifest["source_flags"] == {f"{package.prefix}.c": ["-O3"]}
    assert with_source_flags(package, "x.c", None) is package


def test_knob_table_reports_failures_and_missing_values():
    rows = [KnobRow("s", "es", "package defaults", 1.5e-6, 2.0, 4.5, 1e-13),
            KnobRow("s", "vi", "solver -O2", None, None, None, None, 0.7, "status 1\nmore")]
    table = knob_table(rows).splitlines()
    assert table[2] == "| s | es | package defaults | 1.5 | 2.00 | 4.50 | 1e-13 | - |"
    assert table[3] == "| s | vi | solver -O2 | failed: status 1 | - | - | - | 0.7 |"
