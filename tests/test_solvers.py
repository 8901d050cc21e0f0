"""Compile tier: the generated solvers of all three schemes, built and run through the Python
runtime."""
from __future__ import annotations

import ctypes
import re
import subprocess

import numpy as np
import pytest

from chaingen.runtime import NewtonError, NewtonOptions

from helpers import OWN_SCENES, REFERENCE_SCENES, ROOT, load, solver_for

pytestmark = pytest.mark.compile

GENERATED = ROOT / "generated"

rng = np.random.default_rng(7)
STANDARD = dict(dt=0.01, n_steps=5000)   # thesis Table 5.1: 50 s at dt = 0.01 s


def standard_run(name, quadrature, method="es", gradient="exact"):
    scene = load(name)
    return solver_for(name, method, quadrature, gradient=gradient).simulate(
        scene.initial_angles, scene.initial_velocities, **STANDARD)


def random_step_point(solver, scene):
    """A state from random joint-space values and a Newton iterate near its solution."""
    phi, phidot = rng.uniform(-np.pi, np.pi, scene.n), rng.normal(0, 1.5, scene.n)
    x0 = solver.initial_state(phi, phidot)
    scale = 0.05 if solver.manifest["method"] == "es" else 0.3
    z = rng.normal(0.0, scale, solver.nz)
    return z, x0


JACOBIAN_CASES = ([("es", quadrature, name) for quadrature in (1, 3)
                   for name in REFERENCE_SCENES + OWN_SCENES]
                  + [(method, 3, name) for method in ("vi", "midpoint")
                     for name in REFERENCE_SCENES + OWN_SCENES])


@pytest.mark.parametrize("method,quadrature,name", JACOBIAN_CASES)
def test_jacobian_matches_central_differences(method, quadrature, name):
    """dF/dz of the generated code against central differences of the generated residual."""
    scene = load(name)
    solver = solver_for(name, method, quadrature)
    for _ in range(3):
        z, x0 = random_step_point(solver, scene)
        dt = rng.uniform(0.001, 0.05)
        _, jacobian = solver.residual_jacobian(z, x0, dt=dt)
        numeric = np.empty_like(jacobian)
        for j in range(solver.nz):
            h = 1e-6 * max(1.0, abs(z[j]))
            up, down = z.copy(), z.copy()
            up[j] += h
            down[j] -= h
            numeric[:, j] = (solver.residual(up, x0, dt=dt)
                             - solver.residual(down, x0, dt=dt)) / (2 * h)
        error = np.abs(jacobian - numeric).max() / np.abs(jacobian).max()
        assert error <= 1e-6, f"relative Jacobian error {error:.2e}"


def test_residual_and_jacobian_agree_on_the_residual():
    solver = solver_for("three_link_mono", "es", 3)
    z, x0 = random_step_point(solver, load("three_link_mono"))
    residual, _ = solver.residual_jacobian(z, x0, dt=0.01)
    np.testing.assert_array_equal(residual, solver.residual(z, x0, dt=0.01))


@pytest.mark.parametrize("name,quadrature", [("three_link_gravity", 1), ("three_link_mono", 1),
                                              ("three_link_mono", 3), ("three_link_multi", 3)])
def test_standard_run_keeps_the_constraints_to_round_off(name, quadrature):
    result = standard_run(name, quadrature)
    assert result.n_steps == 5000 and len(result.samples) == 5001
    assert result.constraint_error.max() <= 1e-12


def test_standard_gravity_run_conserves_energy_to_round_off():
    result = standard_run("three_link_gravity", 1)
    assert np.abs(result.energy_error).max() <= 1e-12


def test_midpoint_rule_energy_error_is_bounded_near_1e_5():
    """Thesis Fig. 5.5a: with K = 1 the spring terms averaged by the quadrature alone (the
    thesis's scheme) give a bounded error of about 1e-5."""
    error = np.abs(standard_run("three_link_mono", 1, gradient="quadrature").energy_error)
    assert 1e-6 <= error.max() <= 1e-4
    first, second = error[:2500].max(), error[2500:].max()
    assert second <= 2.0 * first, "energy error grows: not bounded"


@pytest.mark.parametrize("name", ["three_link_mono", "three_link_multi"])
@pytest.mark.parametrize("quadrature", [1, 3])
def test_the_exact_gradient_holds_the_standard_run_to_round_off(name, quadrature):
    """The default discrete gradient: the energy of the 50 s standard run (5000 steps) stays
    within 1e-12 of its size at K = 1 too, where the quadrature alone leaves ~1e-5 (above)."""
    result = standard_run(name, quadrature)
    assert np.abs(result.energy_error).max() <= 1e-12 * np.abs(result.energy).max()


def test_the_exact_gradient_keeps_the_quadratures_trajectory():
    """The correction is of the quadrature error's size: with K = 3 the angles of the two
    gradients after the 50 s standard run agree far below the scheme's error at dt = 0.01 s
    (about 1e-6 rad after 1 s, docs/model.md section 4)."""
    exact = standard_run("three_link_multi", 3)
    averaged = standard_run("three_link_multi", 3, gradient="quadrature")
    assert np.abs(exact.phi - averaged.phi).max() <= 1e-8


def test_gauss_3_energy_error_is_below_1e_11():
    assert np.abs(standard_run("three_link_mono", 3).energy_error).max() <= 1e-11


@pytest.mark.parametrize("method", ["vi", "midpoint"])
@pytest.mark.parametrize("name", ["three_link_gravity", "three_link_mono"])
def test_joint_space_schemes_standard_run(name, method):
    """Thesis Fig. 5.3b/c: bounded energy error of order 1e-4..1e-3; vi keeps |q_i| = 1."""
    result = standard_run(name, 3, method)
    error = np.abs(result.energy_error)
    assert 1e-5 <= error.max() <= 2e-3
    # Bounded, not drifting: over four times the standard run (the error is spiky on this
    # chaotic motion, so halves of one run are too short to tell) the last quarter stays
    # within twice the first.
    scene = load(name)
    long_error = np.abs(solver_for(name, method, 3).simulate(
        scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=20000).energy_error)
    assert long_error[15000:].max() <= 2.0 * long_error[:5000].max(), "energy error drifts"
    if method == "vi":
        assert result.constraint_error.max() <= 1e-13
    else:
        assert result.constraint_error.max() == 0.0


@pytest.mark.parametrize("method", ["vi", "midpoint"])
def test_joint_space_energy_error_has_order_2(method):
    scene = load("three_link_gravity")
    solver = solver_for("three_link_gravity", method, 3)
    errors = [np.abs(solver.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                                     n_steps=round(50 / dt)).energy_error).max()
              for dt in (0.02, 0.01)]
    assert np.log2(errors[0] / errors[1]) == pytest.approx(2.0, abs=0.4)


@pytest.mark.parametrize("name", REFERENCE_SCENES)
def test_the_three_schemes_agree_at_small_steps(name):
    """At dt = 1e-4 all three schemes agree to 1e-6 rad at t = 1 s."""
    scene = load(name)
    finals = [solver_for(name, method, 3).simulate(
        scene.initial_angles, scene.initial_velocities, dt=1e-4, n_steps=10000,
        every=10000).phi[-1] for method in ("es", "vi", "midpoint")]
    for other in finals[1:]:
        difference = (finals[0] - other + np.pi) % (2 * np.pi) - np.pi
        assert np.abs(difference).max() <= 1e-6


@pytest.mark.parametrize("method", ["vi", "midpoint"])
def test_damped_joint_space_schemes_dissipate(method):
    import dataclasses

    from chaingen.simulation import build_solver
    scene = load("three_link_mono")
    damped = dataclasses.replace(scene, links=tuple(
        dataclasses.replace(link, damping=0.5) for link in scene.links))
    result = build_solver(damped, method, 3).simulate(
        scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=2000)
    assert result.energy[-1] < result.energy[0] - 0.5


def test_energy_error_of_the_spring_terms_has_order_2k():
    """With the quadrature alone (the thesis's scheme), halving dt divides the K = 1 energy
    error by about 4, and the K = 2 error by about 16."""
    scene = load("three_link_mono")
    for quadrature, order in ((1, 2), (2, 4)):
        solver = solver_for("three_link_mono", "es", quadrature, gradient="quadrature")
        errors = []
        for dt in (0.04, 0.02):
            result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                                     n_steps=round(5.0 / dt))
            errors.append(np.abs(result.energy_error).mean())
        assert np.log2(errors[0] / errors[1]) == pytest.approx(order, abs=0.5)


def test_damped_energy_decreases_monotonically():
    import dataclasses

    from chaingen.simulation import build_solver
    scene = load("three_link_mono")
    damped = dataclasses.replace(scene, links=tuple(
        dataclasses.replace(link, damping=0.2) for link in scene.links))
    result = build_solver(damped, "es", 3).simulate(
        scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=1000)
    assert np.all(np.diff(result.energy) <= 1e-12)
    assert result.energy[-1] < result.energy[0] - 0.1


def test_failed_newton_solve_raises_with_the_step():
    scene = load("three_link_mono")
    solver = solver_for("three_link_mono", "es", 3)
    with pytest.raises(NewtonError, match=r"step 1 \(t = 0 s") as caught:
        solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=10,
                        options=NewtonOptions(max_iterations=1))
    assert caught.value.status == 1 and caught.value.step == 1
    assert len(caught.value.result.samples) == 1      # only the initial row is valid
    with pytest.raises(NewtonError, match="did not converge"):
        solver.step(solver.initial_state(scene.initial_angles, scene.initial_velocities),
                    dt=0.01, options=NewtonOptions(max_iterations=1))


@pytest.mark.parametrize("method", ["vi", "midpoint"])
def test_the_energy_check_refuses_a_step_that_misses_the_balance(method):
    """vi and midpoint keep the energy balance only up to their error: a step whose balance
    error exceeds energy_tol (T_0 + T_1) fails the check (ENERGY_JUMP) and is split; when every
    half fails too, it is refused. With a tolerance no step meets, the step fails; with the
    default, the same step passes, and a resolved 50 s run never trips it. (From rest, the
    halves' balance error is within the check's round-off floor: the step starts at t = 1 s.)"""
    from chaingen.runtime.contract import STATUS_CODES
    scene = load("three_link_mono")
    solver = solver_for("three_link_mono", method, 3)
    moving = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                             n_steps=100, every=100)
    x0 = solver.initial_state(moving.phi[-1], moving.omega[-1])
    with pytest.raises(NewtonError, match="energy balance") as caught:
        solver.step(x0, dt=0.01, options={"energy_tol": 1e-300})
    assert caught.value.status == STATUS_CODES["ENERGY_JUMP"]
    assert np.all(np.isfinite(solver.step(x0, dt=0.01).x1))
    assert np.all(np.isfinite(solver.step(x0, dt=0.01, options={"energy_tol": 0.0}).x1))
    with pytest.raises(ValueError, match=r"^NewtonOptions\.energy_tol: must be >= 0"):
        solver.step(x0, dt=0.01, options={"energy_tol": -1.0})
    run = solver.simulate(scene.initial_angles, scene.initial_velocities, **STANDARD)
    assert run.split_steps == 0


def test_es_has_no_energy_check():
    """es keeps the balance at every root: its package has no check, and energy_tol changes
    nothing."""
    scene = load("three_link_mono")
    solver = solver_for("three_link_mono", "es", 3)
    assert not solver.manifest["energy_check"]
    x0 = solver.initial_state(scene.initial_angles, scene.initial_velocities)
    np.testing.assert_array_equal(solver.step(x0, dt=0.01, options={"energy_tol": 1e-300}).x1,
                                  solver.step(x0, dt=0.01, options={"energy_tol": 0.0}).x1)


def test_step_matches_simulate():
    scene = load("three_link_multi")
    solver = solver_for("three_link_multi", "es", 3)
    x = solver.initial_state(scene.initial_angles, scene.initial_velocities)
    for _ in range(10):
        step = solver.step(x, dt=0.01)
        x = step.x1
        assert 1 <= step.iterations <= 5
    result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                             n_steps=10, every=5)
    np.testing.assert_array_equal(result.t, [0.0, 0.05, 0.1])
    np.testing.assert_allclose(result.phi[-1], solver.outputs(x)[0], rtol=0, atol=1e-15)


def test_bad_arguments_are_refused():
    solver = solver_for("three_link_mono", "es", 3)
    # A dt that is not > 0 and finite is named in Python (C's own refusal, BAD_ARGUMENT, is
    # tested in test_c_fuzz and runtime/c/tests/test_runtime.c).
    with pytest.raises(ValueError, match="dt: must be > 0 and finite, got -0.01"):
        solver.step(np.zeros(solver.nx), dt=-0.01)
    with pytest.raises(ValueError, match="12 entries"):
        solver.step(np.zeros(3), dt=0.01)
    # Every entry point checks its pointers: NULL gives BAD_ARGUMENT (or, for the two that
    # return nothing, no effect; UNAVAILABLE for one the package lacks), never a crash.
    library = ctypes.CDLL(str(solver.library_path))   # its own function objects, untyped
    for name, entry in solver.manifest["entry_points"].items():
        function = getattr(library, f"{solver.prefix}_{name}")
        if not entry["parameters"] or name == "sample_count":
            continue
        function.argtypes = None
        function.restype = ctypes.c_int
        status = function(*[None if "*" in c_type else 0
                            for _, c_type in entry["parameters"]])
        if entry["returns"] == "int":
            assert status == (4 if entry["available"] else 11), name


def _symbols(library, *flags):
    out = subprocess.run(["nm", "-D", *flags, str(library)], capture_output=True, text=True,
                         check=True).stdout
    return [line.split()[-1] for line in out.splitlines() if line.strip()]


@pytest.mark.parametrize("method", ["es", "vi", "midpoint"])
@pytest.mark.parametrize("name", REFERENCE_SCENES)
def test_exactly_the_header_api_is_exported(name, method):
    """Only prefixed symbols, and of those only the API the header declares: CasADi's model
    functions and helpers stay hidden."""
    solver = solver_for(name, method, 3, sensitivities=True)
    exported = set(_symbols(solver.library_path, "--defined-only"))
    header = (GENERATED / solver.prefix / f"{solver.prefix}.h").read_text()
    api = set(re.findall(rf"^{solver.prefix.upper()}_API\n[\w ]+?\**\s*({solver.prefix}_\w+)\(",
                         header, flags=re.M))
    assert f"{solver.prefix}_step" in api and f"{solver.prefix}_step_sensitivities" in api
    assert exported == api


@pytest.mark.parametrize("method", ["es", "vi", "midpoint"])
@pytest.mark.parametrize("name", REFERENCE_SCENES)
def test_nothing_is_allocated(name, method):
    """The library imports no allocator at all, so neither step nor simulate can allocate."""
    undefined = set(_symbols(solver_for(name, method, 3).library_path, "--undefined-only"))
    allocators = {"malloc", "calloc", "realloc", "free", "aligned_alloc", "posix_memalign"}
    assert not {s.split("@")[0] for s in undefined} & allocators


def test_two_solvers_run_side_by_side():
    """No global mutable state: interleaved steps of two instances equal separate runs."""
    from chaingen.runtime import Solver
    first = solver_for("three_link_mono", "es", 3)
    second = Solver(first.library_path, first.manifest)   # same library, own workspace
    scene = load("three_link_mono")
    xa = first.initial_state(scene.initial_angles, scene.initial_velocities)
    xb = second.initial_state(np.zeros(3), np.ones(3))
    alone_a, alone_b = xa.copy(), xb.copy()
    for _ in range(20):
        xa = first.step(xa, dt=0.01).x1
        xb = second.step(xb, dt=0.01).x1
    for _ in range(20):
        alone_a = first.step(alone_a, dt=0.01).x1
    for _ in range(20):
        alone_b = second.step(alone_b, dt=0.01).x1
    np.testing.assert_array_equal(xa, alone_a)
    np.testing.assert_array_equal(xb, alone_b)


def test_the_exact_gradient_keeps_the_step_jacobians_at_rest():
    """A controller linearises the step at a held posture (zero rates): there the exact
    gradient's correction has faded out, and the step's Jacobians are the quadrature's. (Its
    first version divided round-off by |dd|^2 there: ds/ds was off by 16 and an LQR designed
    on it diverged.)"""
    from chaingen.simulation import build_solver

    scene = load("four_link_actuated")
    target = np.array([np.pi / 2, 0.0, 0.0, 0.0])
    maps = {}
    for gradient in ("exact", "quadrature"):
        solver = build_solver(scene, "es", 3, gradient=gradient)
        hold = solver.holding_torques(target)
        maps[gradient] = solver.step_sensitivities(
            solver.initial_state(target, np.zeros(4)), hold, 0.001)
    for name in ("ds_ds", "ds_du"):
        exact, averaged = getattr(maps["exact"], name), getattr(maps["quadrature"], name)
        assert np.abs(exact - averaged).max() <= 1e-9 * np.abs(averaged).max(), name
