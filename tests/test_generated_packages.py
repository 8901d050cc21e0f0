"""The checked-in generated/ packages: reproduced byte for byte, and buildable on their own."""
from __future__ import annotations

import json
import shutil
import subprocess

import pytest

from chaingen.runtime import contract
from chaingen.studies.reference_packages import REFERENCE_PACKAGES, differences, reference_package

from helpers import ROOT, require_tools

GENERATED = ROOT / "generated"
STRICT = " ".join(contract.STRICT_FLAGS)


@pytest.mark.parametrize("scene,method,quadrature", [
    pytest.param(*package, marks=pytest.mark.heavy if package[1] == "vi" else ())
    for package in REFERENCE_PACKAGES])
def test_generated_package_is_reproduced_byte_for_byte(scene, method, quadrature):
    """vi's packages take a few seconds each to derive: heavy."""
    package = reference_package(scene, method, quadrature)
    assert differences(package, GENERATED / package.prefix) == []


def test_differences_name_what_changed(tmp_path):
    package = reference_package("three_link_gravity", "es", 1)
    assert len(differences(package, tmp_path / "none")) == len(package.files)
    copy = tmp_path / package.prefix
    copy.mkdir()
    for name, text in package.files.items():
        (copy / name).write_text(text)
    (copy / "stale.c").write_text("")
    (copy / "Makefile").write_text(package.files["Makefile"] + "\n")
    assert differences(package, copy) == [f"{package.prefix}/stale.c: not generated any more",
                                           f"{package.prefix}/Makefile: differs"]


@pytest.mark.compile
def test_makefile_builds_the_package_with_strict_flags(tmp_path):
    source = GENERATED / "three_link_mono_es"
    shutil.copytree(source, tmp_path / "pkg")
    result = subprocess.run(["make", f"CFLAGS=-O2 {STRICT}"], cwd=tmp_path / "pkg",
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "pkg" / "libthree_link_mono_es.a").exists()
    assert (tmp_path / "pkg" / "libthree_link_mono_es.so").exists()


@pytest.mark.tools
def test_cmake_builds_and_installs_the_package(tmp_path):
    require_tools("cmake")
    source = GENERATED / "three_link_multi_es"
    build, prefix = tmp_path / "build", tmp_path / "install"
    steps = [["cmake", "-S", str(source), "-B", str(build), f"-DCMAKE_C_FLAGS={STRICT}",
              f"-DCMAKE_INSTALL_PREFIX={prefix}"],
             ["cmake", "--build", str(build)],
             ["cmake", "--install", str(build)]]
    for step in steps:
        result = subprocess.run(step, capture_output=True, text=True)
        assert result.returncode == 0, result.stdout + result.stderr
    assert list(prefix.rglob("three_link_multi_es.h"))
    assert list(prefix.rglob("libthree_link_multi_es.a"))


@pytest.mark.compile
def test_embedding_program_runs_without_python(tmp_path):
    """A C program using only the header and sources: simulate, then check constraints."""
    package = GENERATED / "three_link_gravity_es"
    program = tmp_path / "main.c"
    program.write_text(r"""
#include <stdio.h>
#include "three_link_gravity_es.h"

int main(void)
{
    static three_link_gravity_es_workspace workspace;
    static double samples[101 * THREE_LINK_GRAVITY_ES_NSAMPLE];
    double phi[3] = {0.7853981633974483, 0.3, 0.3}, phidot[3] = {0.0, 0.0, 0.0};
    double x[THREE_LINK_GRAVITY_ES_NX];
    three_link_gravity_es_stats stats;
    int status = three_link_gravity_es_initial_state(phi, phidot, NULL, 0, x, &workspace);
    if (status == THREE_LINK_GRAVITY_ES_OK)
        status = three_link_gravity_es_simulate(x, 0.0, 0.01, 100, 1, NULL, 0, NULL, 0, NULL,
                                                &workspace,
                                                samples, NULL, &stats);
    printf("%d %ld %.17g %.17g\n", status, stats.steps,
           samples[100 * THREE_LINK_GRAVITY_ES_NSAMPLE + 7] - samples[7],
           samples[100 * THREE_LINK_GRAVITY_ES_NSAMPLE + 8]);
    return status;
}
""")
    binary = tmp_path / "main"
    sources = json.loads((package / "chaingen.json").read_text())["sources"]
    compile_ = subprocess.run(["cc", *STRICT.split(), "-O2", f"-I{package}", str(program),
                               *(str(package / name) for name in sources), "-lm", "-o",
                               str(binary)],
                              capture_output=True, text=True)
    assert compile_.returncode == 0, compile_.stderr
    run = subprocess.run([str(binary)], capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr
    status, steps, energy_change, constraint = run.stdout.split()
    assert (int(status), int(steps)) == (0, 100)
    assert abs(float(energy_change)) <= 1e-13 and float(constraint) <= 1e-13


@pytest.mark.compile
def test_runtime_loads_a_package_directory_and_round_trips_the_trajectory(tmp_path):
    """Solver.from_directory builds a checked-in package; write/read_trajectory round-trip."""
    import numpy as np

    from chaingen.runtime import Solver, write_trajectory
    from chaingen.runtime.trajectory import read_trajectory

    solver = Solver.from_directory(GENERATED / "three_link_gravity_es")
    result = solver.simulate([0.7853981633974483, 0.3, 0.3], [0.0, 0.0, 0.0], dt=0.01,
                             n_steps=50, every=5)
    assert np.abs(result.energy_error).max() <= 1e-13
    columns, rows = read_trajectory(write_trajectory(result, tmp_path / "traj.csv"))
    assert columns == result.columns
    np.testing.assert_array_equal(rows, result.samples)
