"""es's Newton systems solved by the Jacobian's factors (docs/model.md, section 18;
runtime/c/chaingen_arm_solve.h): the factors assemble the Jacobian, and a package that solves by
them steps, converges and differentiates as dense LU does."""
from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

from chaingen.generate.casadi_functions import scheme_functions
from chaingen.studies.bench.scenes import scaling_scene
from chaingen.symbolic.schemes import build_scheme, es

from helpers import load, require_tools

rng = np.random.default_rng(20261203)


@pytest.fixture
def arm_solve(monkeypatch):
    """Set whether es packages solve by the factors, whatever their length:
    arm_solve(True | False)."""
    def choose(on: bool) -> None:
        monkeypatch.setattr(es, "ARM_SOLVE_MIN_LINKS", 1 if on else 10 ** 9)
    return choose


def assembled_jacobian(factors: np.ndarray, pattern, n: int) -> np.ndarray:
    """[[M + B^T H B, B^T G_mu], [G_c B, 0]] from the factors, with B the inverse of the joint
    recursion P (arms to q) built column by column in numpy: an independent reading of the
    layout chaingen_arm_solve.h documents."""
    rows, columns = pattern
    nh = len(rows)
    H = np.zeros((2 * n, 2 * n))
    H[list(rows), list(columns)] = factors[:nh]
    g_mu, g_c = factors[nh:nh + 2 * n], factors[nh + 2 * n:nh + 4 * n]
    masses, maps = factors[nh + 4 * n:nh + 5 * n], factors[nh + 5 * n:].reshape(n, 2, 2)
    P = np.zeros((2 * n, 2 * n))
    for column in range(2 * n):
        arms = np.eye(2 * n)[column].reshape(n, 2)
        joint = np.zeros(2)
        for k in range(n):
            com = joint + arms[k]
            P[k, column], P[n + k, column] = com
            joint = joint + maps[k] @ arms[k]
    B = np.linalg.inv(P)
    G_mu, G_c = np.zeros((2 * n, n)), np.zeros((n, 2 * n))
    for k in range(n):
        G_mu[2 * k:2 * k + 2, k] = g_mu[2 * k:2 * k + 2]
        G_c[k, 2 * k:2 * k + 2] = g_c[2 * k:2 * k + 2]
    M = np.diag(np.concatenate([masses, masses]))
    return np.block([[M + B.T @ H @ B, B.T @ G_mu], [G_c @ B, np.zeros((n, n))]])


@pytest.mark.parametrize("name, parameters", [
    ("scaling-7", ()),                       # multi-articular springs at both ends
    ("four_link_actuated", ()),              # torques and damping
    ("four_link_actuated", ("all",)),        # every number a run-time parameter
    ("five_link_biarticular", ()),           # COMs off the links' axes
    ("four_link_pbc", ()),                   # a control law on every joint: H fills up
    ("four_link_pbc_partial", ()),           # ... on three of four joints
    ("four_link_pbc", ("all",)),             # its gains and target run-time parameters too
])
def test_the_factors_assemble_the_newton_jacobian(arm_solve, name, parameters):
    arm_solve(True)
    scene = scaling_scene(7) if name == "scaling-7" else load(name)
    n = scene.n
    scheme = build_scheme(scene, "es", 3, parameters)
    functions = scheme_functions(scheme, "t", sensitivities=False)
    assert functions.arm_pattern is not None
    q = ([np.array(functions.parameters(list(scheme.parameter_values))).ravel()]
         if scheme.parameter_paths else [])
    for _ in range(3):
        x0 = np.array(functions.initial_state(rng.uniform(-1, 1, n), rng.normal(0, 1, n),
                                              *q)).ravel()
        point = ([rng.normal(0, 0.1, 3 * n), x0]
                 + ([rng.normal(0, 1, len(scene.actuated_joints))]
                    if scene.actuated_joints else []) + q + [0.01])
        F, J = (np.array(value) for value in functions.residual_jacobian(*point))
        F_factors, factors = (np.array(value).ravel()
                              for value in functions.newton_factors(*point))
        np.testing.assert_array_equal(F_factors, F.ravel())
        assembled = assembled_jacobian(factors, functions.arm_pattern, n)
        np.testing.assert_allclose(assembled, J, rtol=0, atol=1e-12 * np.abs(J).max())


def test_short_chains_keep_dense_lu_and_long_ones_solve_by_the_factors():
    assert build_scheme(scaling_scene(es.ARM_SOLVE_MIN_LINKS - 1), "es", 3).arm_space is None
    assert build_scheme(scaling_scene(es.ARM_SOLVE_MIN_LINKS), "es", 3).arm_space is not None
    assert build_scheme(scaling_scene(es.ARM_SOLVE_MIN_LINKS), "vi", 3).arm_space is None


@pytest.mark.heavy
def test_h_has_a_few_entries_per_link():
    """dh/dw is banded: each link's arm couples to its neighbours' and, through a
    multi-articular spring, to those over its span; not to the whole chain."""
    for n in (10, 20):
        scheme = build_scheme(scaling_scene(n), "es", 3, order=2)
        pattern = scheme_functions(scheme, "t", sensitivities=False).arm_pattern
        rows, columns = np.array(pattern[0]), np.array(pattern[1])
        links_apart = np.abs(rows // 2 - columns // 2)
        assert links_apart.max() <= 3      # the scaling chain's widest spring spans 3 joints
        assert len(rows) <= 16 * n


def packages(name: str, arm_solve, **build):
    """The solver of a scene built twice: by dense LU, then by the factors (generated each
    time: build_solver's index keys by the inputs, and the switch is a constant of the code)."""
    from chaingen import Solver
    from chaingen.generate.package import generate_package

    scene = scaling_scene(8) if name == "scaling-8" else load(name)
    solvers, arm = [], []
    for on in (False, True):
        arm_solve(on)
        package = generate_package(scene, "es", 3, **build)
        solvers.append(Solver.from_files(package.files))
        # The model table's nonzeros of H: 0 for the dense LU (chaingen_runtime.h).
        arm.append(".arm_nh = 0," not in package.files[f"{package.prefix}.c"])
    assert [s.manifest["prefix"] for s in solvers] == [solvers[0].manifest["prefix"]] * 2
    assert arm == [False, True]
    return scene, solvers


@pytest.mark.compile
@pytest.mark.parametrize("name, order", [("scaling-8", 2), ("four_link_actuated", 2),
                                         ("five_link_biarticular", 2),
                                         ("four_link_actuated", 4)])
@pytest.mark.slow
def test_the_factored_solve_steps_as_dense_lu(arm_solve, name, order):
    """The same root: trajectories agree to Newton's tolerance, the same iterations, energy
    and constraint errors at the same round-off; and the public residual_jacobian, formed from
    the factors in C, equals CasADi's."""
    scene, (dense, factored) = packages(name, arm_solve, sensitivities=False, order=order)
    torques = (np.tile(0.3 * np.sin(np.arange(300) * 0.05)[:, None],
                       (1, len(scene.actuated_joints))) if scene.actuated_joints else None)
    runs = [solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                            n_steps=300, torques=torques) for solver in (dense, factored)]
    np.testing.assert_allclose(runs[1].phi, runs[0].phi, rtol=0, atol=1e-9)
    # The C residual_jacobian formed from the factors is CasADi's dense one.
    x0 = dense.initial_state(np.array(scene.initial_angles) + 0.1,
                             np.array(scene.initial_velocities) + 0.3)
    z = rng.normal(0, 0.01, dense.nz)
    u = np.full(len(scene.actuated_joints), 0.2) if scene.actuated_joints else None
    F0, J0 = dense.residual_jacobian(z, x0, u, 0.01)
    F1, J1 = factored.residual_jacobian(z, x0, u, 0.01)
    np.testing.assert_array_equal(F1, F0)
    np.testing.assert_allclose(J1, J0, rtol=0, atol=1e-12 * np.abs(J0).max())
    assert abs(runs[1].mean_newton_iterations - runs[0].mean_newton_iterations) <= 0.05
    for run in runs:
        balance = np.max(np.abs(run.balance_error))
        assert balance <= 1e-6 * max(1.0, np.max(np.abs(run.energy)))
        assert np.max(run.constraint_error) <= 1e-13


@pytest.mark.compile
def test_a_jacobian_asked_between_kept_steps_changes_no_state(arm_solve):
    """residual_jacobian writes its factors where the Newton loop keeps its own: simplified
    Newton (the Jacobian kept across steps) then factorises afresh, and the run reaches the
    same states as without the call."""
    scene, (_, factored) = packages("scaling-8", arm_solve, sensitivities=False)
    options = {"reuse_jacobian": 1}
    start = factored.initial_state(scene.initial_angles, scene.initial_velocities)
    runs = []
    for interrupted in (False, True):
        factored.reset()
        x, states = start, []
        for k in range(6):
            if interrupted and k == 3:
                factored.residual_jacobian(rng.normal(0, 1.0, factored.nz), x + 0.5, dt=0.01)
            x = factored.step(x, dt=0.01, options=options).x1
            states.append(x)
        runs.append(np.array(states))
    np.testing.assert_allclose(runs[1], runs[0], rtol=0, atol=1e-12)


@pytest.mark.compile
@pytest.mark.parametrize("order", [2, 4])
def test_step_sensitivities_by_the_factors_equal_dense_lus(arm_solve, order):
    scene, (dense, factored) = packages("four_link_actuated", arm_solve, sensitivities=True,
                                        order=order)
    x0 = dense.initial_state(np.array(scene.initial_angles) + 0.2,
                             np.array(scene.initial_velocities) + 0.5)
    u = np.full(len(scene.actuated_joints), 0.4)
    results = [solver.step_sensitivities(x0, u, 0.01) for solver in (dense, factored)]
    for field in ("x1", "ds_ds", "ds_du"):
        expected, got = getattr(results[0], field), getattr(results[1], field)
        np.testing.assert_allclose(got, expected, rtol=0,
                                   atol=1e-9 * max(1.0, np.abs(expected).max()))


@pytest.mark.compile
@pytest.mark.parametrize("name", ["four_link_pbc", "four_link_pbc_partial"])
@pytest.mark.slow
def test_a_controlled_step_by_the_factors_is_dense_lus(arm_solve, name):
    """A control law's torque couples its joint's arms to all outboard ones, so H is dense;
    the factors take it as they take a banded H. The same root as dense LU: trajectories to
    Newton's tolerance with the same iterations, H_d's balance at round-off, the torques
    control_torques reports and the step sensitivities the same."""
    scene, (dense, factored) = packages(name, arm_solve, sensitivities=True)
    runs = [solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.02,
                            n_steps=300) for solver in (dense, factored)]
    np.testing.assert_allclose(runs[1].phi, runs[0].phi, rtol=0, atol=1e-9)
    assert abs(runs[1].mean_newton_iterations - runs[0].mean_newton_iterations) <= 0.05
    for run in runs:
        assert np.max(np.abs(run.balance_error)) <= 1e-12 * np.max(np.abs(run.energy))
        assert np.max(run.constraint_error) <= 1e-13
    x0 = dense.initial_state(np.array(scene.initial_angles) + 0.2,
                             np.array(scene.initial_velocities) + 0.5)
    u = np.full(len(scene.actuated_joints), 0.3)
    steps = []
    for solver in (dense, factored):
        solver.reset()
        steps.append(solver.control_torques(x0, u, 0.02))
    np.testing.assert_allclose(steps[1].tau, steps[0].tau, rtol=0,
                               atol=1e-10 * np.abs(steps[0].tau).max())
    np.testing.assert_allclose(steps[1].x1, steps[0].x1, rtol=0, atol=1e-10)
    results = [solver.step_sensitivities(x0, u, 0.02) for solver in (dense, factored)]
    for field in ("x1", "ds_ds", "ds_du"):
        expected, got = getattr(results[0], field), getattr(results[1], field)
        np.testing.assert_allclose(got, expected, rtol=0,
                                   atol=1e-9 * max(1.0, np.abs(expected).max()))


@pytest.mark.tools
@pytest.mark.slow
def test_a_factored_package_is_clean_under_valgrind_and_the_sanitizers(arm_solve, tmp_path):
    """COMs off the links' axes (general 2 x 2 maps A_k), multi-articular springs: the example
    program and a call of step_sensitivities (the factored solve with many right-hand sides)
    under memcheck and under ASan/UBSan with the strict flags."""
    require_tools("gcc", "valgrind")
    from test_standalone_package import SANITIZE, STRICT, valgrind_clean

    from chaingen.generate.package import generate_package, write_package

    arm_solve(True)
    package = write_package(generate_package(load("five_link_biarticular"), "es", 3),
                            tmp_path / "package")
    manifest = json.loads((package / "chaingen.json").read_text())
    prefix, sources = manifest["prefix"], manifest["sources"]
    assert "ARM_H_ROW" in (package / f"{prefix}.c").read_text() and manifest["sensitivities"]
    (package / "sensitivities.c").write_text(f"""#include "{prefix}.h"
int main(void)
{{
    static {prefix}_workspace ws;
    double phi[5] = {{0.3, -0.2, 0.1, 0.4, -0.3}}, phidot[5] = {{0.5, 0.0, -0.3, 0.2, 0.1}};
    double x[{prefix.upper()}_NX], x1[{prefix.upper()}_NX], ds_ds[100];
    int iterations, status;
    {prefix}_workspace_init(&ws);
    status = {prefix}_initial_state(phi, phidot, NULL, 0, x, &ws);
    if (status == 0) {{
        status = {prefix}_step_sensitivities(x, NULL, 0, NULL, 0, 0.01, x1, ds_ds, NULL, NULL,
                                              NULL, &ws, &iterations);
    }}
    return status;
}}
""")
    for program, arguments in (("example.c", ["0.5"]), ("sensitivities.c", [])):
        for name, flags, runner in (("memcheck", ["-g", "-O1"],
                                     ["valgrind", "--error-exitcode=99", "--track-origins=yes"]),
                                    ("sanitized", SANITIZE, [])):
            binary = tmp_path / f"{program}.{name}"
            subprocess.run(["gcc", *flags, *STRICT, f"-I{package}",
                            *(str(package / s) for s in sources), str(package / program),
                            "-lm", "-o", str(binary)], check=True, capture_output=True)
            result = subprocess.run([*runner, str(binary), *arguments], capture_output=True,
                                    text=True)
            if runner:
                valgrind_clean(result)
            else:
                assert result.returncode == 0, result.stderr
