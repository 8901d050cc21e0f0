"""A spatial run is a function of its inputs, bit for bit: the same run twice, the same runs on
six threads at once and alone, and (tools tier) the package's C under valgrind and natively.

Every scheme (and es at order 6, its Galerkin step), on scenes/spatial_three_link.toml with a
torque on its actuated joint (joint 3) and its damped joint 2. Compile tier; the valgrind
comparison is tools tier.

glibc's libm chooses its code for sin, cos, exp ... by the CPU it runs on (ifunc): FMA and AVX2
versions where the CPU has them, SSE2 ones elsewhere, whose results may differ in the last bit.
valgrind reports a CPU of its own, so under valgrind libm may take other code than in a native
run on the same machine; a vi trajectory was seen to differ so in its last bits between the
two. Both runs of that comparison therefore set GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA
(glibc 2.33 and later), which makes libm take the SSE2 code in both: what is compared is
chaingen's C, not two libm versions. Measured here (glibc 2.36, valgrind 3.19, a CPU with FMA
and AVX2): the setting acts (a probe of sin, cos, exp, log, atan2 and pow at 2e6 arguments
gives other bits natively with it than without), and this valgrind takes the FMA code as the
native run does, so the three schemes' bits agreed without the setting too.
"""
from __future__ import annotations

import json
import os
import subprocess
import threading

import numpy as np
import pytest

from chaingen.spatial import load_spatial_scene

from helpers import ROOT, require_tools

SCENE = load_spatial_scene(ROOT / "scenes" / "spatial_three_link.toml")
DT, STEPS, EVERY = 0.005, 200, 1
METHODS = ("midpoint", "vi", "es")
#: (method, order) of every package compared: each scheme's own step, and es at order 6, which
#: composes another step (its k = 1 Galerkin step in joint angles, docs/model.md 16).
SCHEMES = tuple((method, 2) for method in METHODS) + (("es", 6),)
THREADS = 6
#: The libm code of both runs of the valgrind comparison (the module docstring says why).
SAME_LIBM = "glibc.cpu.hwcaps=-AVX2,-FMA"


def torques(steps: int = STEPS) -> np.ndarray:
    """A torque on joint 3 that varies each step (N m)."""
    return 0.4 * np.sin(0.05 * np.arange(steps))[:, None]


def starts(count: int):
    rng = np.random.default_rng(33)
    return [(np.asarray(SCENE.initial_angles) + rng.uniform(-0.3, 0.3, SCENE.n),
             rng.uniform(-0.5, 0.5, SCENE.n)) for _ in range(count)]


@pytest.fixture(scope="module", params=SCHEMES, ids=lambda scheme: f"{scheme[0]}-order-{scheme[1]}")
def solver(request):
    from chaingen.simulation import build_solver

    method, order = request.param
    return build_solver(SCENE, method, sensitivities=False, order=order)


def run(solver, phi, omega) -> np.ndarray:
    """A simulation and a warm-started sequence of steps (the Newton history of this thread),
    their samples and states in one array."""
    result = solver.simulate(phi, omega, dt=DT, n_steps=STEPS, every=EVERY, torques=torques())
    solver.reset()
    x = solver.initial_state(phi, omega)
    chained = []
    for u in torques(40):
        x = solver.step(x, u, DT).x1
        chained.append(x)
    return np.concatenate([result.samples.ravel(), np.ravel(chained)])


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.compile
def test_the_same_run_twice_gives_the_same_bits(solver):
    phi, omega = starts(1)[0]
    first, second = run(solver, phi, omega), run(solver, phi, omega)
    assert np.all(np.isfinite(first)) and same_bits(first, second)
    # The run moved the chain: the comparison is of a real trajectory.
    result = solver.simulate(phi, omega, dt=DT, n_steps=STEPS, torques=torques())
    assert np.abs(result.phi[-1] - result.phi[0]).max() > 0.01


@pytest.mark.compile
def test_six_threads_at_once_give_the_bits_of_each_run_alone(solver):
    """One Solver, six threads running its simulate and step at once (each with its own
    workspace), five rounds: every result equals the same run made alone, bit for bit."""
    begins = starts(THREADS)
    alone = [run(solver, *start) for start in begins]
    assert not any(same_bits(alone[0], other) for other in alone[1:])   # six different runs
    for _ in range(5):
        results = [None] * THREADS
        barrier = threading.Barrier(THREADS)

        def work(index, results=results, barrier=barrier):
            barrier.wait()        # all six in the C at once
            results[index] = run(solver, *begins[index])

        threads = [threading.Thread(target=work, args=(index,)) for index in range(THREADS)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        for together, single in zip(results, alone):
            assert same_bits(together, single)


DRIVER = r"""
#include <stdio.h>
#include "{prefix}.h"
#define P(name) {upper}_##name
static {prefix}_workspace workspace;
static double samples[({steps} / {every} + 1) * P(NSAMPLE)];
static double u[{steps} * (P(NU) > 0 ? P(NU) : 1)];
int main(void)
{{
    {prefix}_options options;
    double x0[P(NX)], x_final[P(NX)];
    const double phi[P(N_JOINTS)] = {{ {phi} }}, omega[P(N_JOINTS)] = {{ {omega} }};
    const double torque[{steps}] = {{ {torques} }};
    long k, i;
    int status;
    for (k = 0; k < {steps}; ++k) {{
        for (i = 0; i < P(NU); ++i) {{
            u[k * P(NU) + i] = torque[k];
        }}
    }}
    {prefix}_default_options(&options);
    {prefix}_workspace_init(&workspace);
    status = {prefix}_initial_state(phi, omega, NULL, 0, x0, &workspace);
    if (status == 0) {{
        status = {prefix}_simulate(x0, 0.0, {dt!r}, {steps}, {every}, u, P(NU), NULL, 0,
                                   &options, &workspace, samples, x_final, NULL);
    }}
    for (k = 0; status == 0 && k < (long)(sizeof samples / sizeof samples[0]); ++k) {{
        printf("%a\n", samples[k]);
    }}
    for (k = 0; status == 0 && k < P(NX); ++k) {{
        printf("%a\n", x_final[k]);
    }}
    return status;
}}
"""


@pytest.mark.tools
@pytest.mark.parametrize("method, order", SCHEMES)
@pytest.mark.slow
def test_the_package_under_valgrind_gives_the_native_bits(tmp_path, method, order):
    """The package's simulate, compiled with its own flags into a program that prints every
    sample in hexadecimal: under valgrind's memcheck (no errors) the same bits as natively,
    both with glibc's libm held to one code path (SAME_LIBM, the module docstring)."""
    require_tools("gcc", "valgrind")
    from chaingen.generate.package import generate_package, write_package

    package = write_package(generate_package(SCENE, method, 3, sensitivities=False,
                                             order=order), tmp_path / "package")
    manifest = json.loads((package / "chaingen.json").read_text())
    prefix = manifest["prefix"]
    phi, omega = starts(1)[0]
    driver = tmp_path / "bits.c"
    driver.write_text(DRIVER.format(
        prefix=prefix, upper=prefix.upper(), steps=STEPS, every=EVERY, dt=DT,
        phi=", ".join(map(repr, map(float, phi))), omega=", ".join(map(repr, map(float, omega))),
        torques=", ".join(map(repr, map(float, torques()[:, 0])))))
    objects = []
    for source in manifest["sources"]:
        target = tmp_path / f"{source}.o"
        flags = manifest.get("source_flags", {}).get(source, ["-O2"])
        built = subprocess.run(["gcc", "-g", *flags, "-c", str(package / source), f"-I{package}",
                                "-o", str(target)], capture_output=True, text=True, timeout=600)
        assert built.returncode == 0, built.stderr
        objects.append(str(target))
    binary = tmp_path / "bits"
    built = subprocess.run(["gcc", "-g", "-O2", f"-I{package}", str(driver), *objects, "-lm",
                            "-o", str(binary)], capture_output=True, text=True, timeout=300)
    assert built.returncode == 0, built.stderr
    environment = {**os.environ, "GLIBC_TUNABLES": SAME_LIBM}
    native = subprocess.run([str(binary)], capture_output=True, text=True, timeout=300,
                            env=environment)
    assert native.returncode == 0, native.stderr
    checked = subprocess.run(["valgrind", "--error-exitcode=99", "--track-origins=yes",
                              str(binary)], capture_output=True, text=True, timeout=1800,
                             env=environment)
    assert checked.returncode == 0 and "ERROR SUMMARY: 0 errors" in checked.stderr, \
        checked.stderr[-2000:]
    rows = native.stdout.split()
    assert len(rows) == (STEPS // EVERY + 1) * manifest["nsample"] + manifest["nx"]
    assert checked.stdout == native.stdout
