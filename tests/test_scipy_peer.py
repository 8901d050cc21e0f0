"""The SciPy peer (codegen/scipy_peer.py): compiled ODE against SymPy, runs against MuJoCo.

The compiled right-hand side is checked against the SymPy expressions it was generated from,
evaluated independently (lambdify, numpy.linalg.solve instead of the C Cholesky); the compiled
Jacobian against central differences of the compiled right-hand side; whole runs against
MuJoCo's model of the same chain (model.md section 10), which also checks the derivation.
"""
from __future__ import annotations

import dataclasses
import shutil
import subprocess
import warnings

import numpy as np
import pytest
import sympy as sp

from chaingen.reference.scipy_peer import (
    ScipyPeerError,
    compile_ode,
    reference_solution,
    simulate_scipy,
)

from helpers import load

pytestmark = pytest.mark.compile

RHS_SCENES = ("three_link_mono", "three_link_gravity", "three_link_multi", "five_link_biarticular")


def random_states(n: int, count: int, seed: int) -> np.ndarray:
    """States with angles over a full turn and rates of a few rad/s."""
    rng = np.random.default_rng(seed)
    return np.hstack([rng.uniform(-np.pi, np.pi, (count, n)), rng.normal(0, 2, (count, n))])


def wrapped(difference):
    return (np.asarray(difference) + np.pi) % (2 * np.pi) - np.pi


@pytest.mark.parametrize("name", RHS_SCENES)
def test_rhs_agrees_with_sympy(name):
    compiled = compile_ode(load(name))
    ode, n = compiled.ode, compiled.n
    symbols = list(ode.state)
    mass = sp.lambdify(symbols, ode.mass_matrix, "numpy")
    forces = sp.lambdify(symbols, ode.forces, "numpy")
    for y in random_states(n, 5, seed=1):
        expected = np.concatenate([y[n:], np.linalg.solve(np.asarray(mass(*y), dtype=float),
                                                          np.asarray(forces(*y), dtype=float)
                                                          .reshape(-1))])
        actual = compiled.fun(0.0, y)
        assert actual.shape == (2 * n,)
        error = np.abs(actual - expected).max() / np.abs(expected).max()
        assert error <= 1e-12, f"{name}: rhs differs from SymPy by {error:.1e} (relative)"


@pytest.mark.parametrize("name", RHS_SCENES)
def test_jacobian_agrees_with_central_differences(name):
    compiled = compile_ode(load(name))
    ny = 2 * compiled.n
    step = 1e-6
    for y in random_states(compiled.n, 3, seed=2):
        jacobian = compiled.jac(0.0, y)
        assert jacobian.shape == (ny, ny)
        differences = np.empty((ny, ny))
        for j in range(ny):
            dy = np.zeros(ny)
            dy[j] = step
            differences[:, j] = (compiled.fun(0.0, y + dy) - compiled.fun(0.0, y - dy)) / (2 * step)
        error = np.abs(jacobian - differences).max() / np.abs(differences).max()
        assert error <= 1e-6, f"{name}: Jacobian differs from differences by {error:.1e}"


def test_results_are_fresh_arrays():
    """solve_ivp may keep what fun and jac return: a later call must not change it."""
    compiled = compile_ode(load("three_link_mono"))
    first, second = random_states(compiled.n, 2, seed=3)
    rhs, jacobian = compiled.fun(0.0, first), compiled.jac(0.0, first)
    kept_rhs, kept_jacobian = rhs.copy(), jacobian.copy()
    compiled.fun(0.0, second)
    compiled.jac(0.0, second)
    np.testing.assert_array_equal(rhs, kept_rhs)
    np.testing.assert_array_equal(jacobian, kept_jacobian)


def test_compiled_once_per_scene_content():
    """The initial state does not enter the code: a scene that differs only there reuses it."""
    scene = load("three_link_mono")
    moved = dataclasses.replace(scene, initial_angles=(0.1, 0.2, 0.3))
    assert compile_ode(moved) is compile_ode(scene)
    heavier = dataclasses.replace(scene, links=(dataclasses.replace(scene.links[0], mass=2.0),)
                                  + scene.links[1:])
    assert compile_ode(heavier).code_hash != compile_ode(scene).code_hash


@pytest.mark.skipif(shutil.which("nm") is None, reason="needs nm")
def test_only_the_wrapper_is_exported():
    library = compile_ode(load("three_link_mono")).library_path
    listing = subprocess.run(["nm", "-D", "--defined-only", str(library)],
                             capture_output=True, text=True, check=True).stdout
    exported = {line.split()[-1] for line in listing.splitlines() if line.split()[1] in "TDB"}
    assert exported == {"peer_rhs", "peer_jacobian"}


@pytest.fixture(scope="module")
def mujoco_gravity():
    pytest.importorskip("mujoco")
    from chaingen.reference.mujoco_runs import simulate_mujoco
    return simulate_mujoco(load("three_link_gravity"), dt=1e-4, t_end=2.0)


@pytest.mark.parametrize("method", ["DOP853", "Radau"])
def test_run_conserves_energy_and_agrees_with_mujoco(method, mujoco_gravity):
    run = simulate_scipy(load("three_link_gravity"), method, 1e-10, 1e-10, 2.0)
    assert run.status == 0 and run.method == method
    assert run.sample_times[0] == 0.0 and run.sample_times[-1] == 2.0
    assert run.n_steps == len(run.sample_times) - 1
    assert run.energies[0] == pytest.approx(mujoco_gravity.initial_energy, abs=1e-12)
    assert run.max_energy_error <= 1e-6
    assert run.max_energy_error == np.abs(run.energies - run.initial_energy).max()
    error = np.abs(wrapped(run.final_angles - mujoco_gravity.final_angles)).max()
    assert error <= 1e-5, f"{method}: angles differ from MuJoCo by {error:.1e} rad"
    assert np.abs(run.final_velocities - mujoco_gravity.final_velocities).max() <= 1e-4
    assert run.nfev > run.n_steps and run.cpu_time > 0 and run.wall_time > 0
    if method == "Radau":
        assert run.njev > 0 and run.nlu > 0


def test_sample_times_change_the_samples_only():
    """With t_eval the steps, the step count and the final state are those of the plain run.

    nfev may grow: DOP853's interpolant at a sample costs extra evaluations in its step."""
    scene = load("three_link_mono")
    plain = simulate_scipy(scene, "DOP853", 1e-8, 1e-8, 1.0)
    sampled = simulate_scipy(scene, "DOP853", 1e-8, 1e-8, 1.0, sample_times=[0.25, 0.5])
    np.testing.assert_array_equal(sampled.sample_times, [0.25, 0.5])
    assert sampled.energies.shape == (2,)
    assert sampled.n_steps == plain.n_steps and sampled.nfev >= plain.nfev
    np.testing.assert_array_equal(sampled.final_angles, plain.final_angles)
    np.testing.assert_array_equal(sampled.final_velocities, plain.final_velocities)


def test_damped_chain_agrees_with_mujoco_and_loses_energy():
    """four_link_actuated has joint damping; the peer applies no input torques, nor here MuJoCo."""
    pytest.importorskip("mujoco")
    from chaingen.reference.mujoco_runs import simulate_mujoco
    scene = load("four_link_actuated")
    run = simulate_scipy(scene, "DOP853", 1e-10, 1e-10, 1.0)
    reference = simulate_mujoco(scene, dt=1e-4, t_end=1.0)
    assert np.abs(wrapped(run.final_angles - reference.final_angles)).max() <= 1e-5
    assert run.energies[-1] < run.initial_energy - 1e-6


def test_reference_solution_is_tighter_than_the_runs(mujoco_gravity):
    """MuJoCo RK4 at dt = 1e-4 is good to about 1e-12 rad here (model.md 10)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")   # SciPy warns when it raises a too small rtol
        angles, velocities = reference_solution(load("three_link_gravity"), 2.0)
    assert np.abs(wrapped(angles - mujoco_gravity.final_angles)).max() <= 1e-9
    assert np.abs(velocities - mujoco_gravity.final_velocities).max() <= 1e-9


def test_unknown_method_is_named():
    with pytest.raises(ScipyPeerError, match="'RK99'"):
        simulate_scipy(load("three_link_mono"), "RK99", 1e-8, 1e-8, 1.0)


def test_failed_run_raises():
    """Rates so large that the right-hand side overflows: every step is rejected."""
    scene = load("three_link_mono")
    scene = dataclasses.replace(scene, initial_velocities=(1e200,) * scene.n)
    with pytest.raises(ScipyPeerError, match="three-link-mono: solve_ivp DOP853.*not finite"):
        simulate_scipy(scene, "DOP853", 1e-8, 1e-8, 1.0)
