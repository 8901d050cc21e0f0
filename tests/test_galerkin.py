"""The k = 1 Petrov-Galerkin step of es in joint angles and canonical momenta (docs/model.md,
section 16), measured without a compiler: its SymPy residual solved by a numpy Newton. What it
must keep on its own: symmetry (the base of the order-6 composition), order 4 in the angles
and in the rates, energy to the quadrature of its Gauss-Lobatto rule, and the energy balance
with torques and damping."""
from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest
import sympy as sp

from chaingen.symbolic.composition import FROM_ORDER_4
from chaingen.symbolic.schemes import galerkin

from helpers import load


@pytest.mark.fast
@pytest.mark.parametrize("points", [3, 4, 5, 6])
def test_gauss_lobatto_rule_is_exact_to_degree_2n_minus_3_and_no_further(points):
    nodes, weights = map(np.array, galerkin.gauss_lobatto_nodes(points))
    assert nodes[0] == 0.0 and nodes[-1] == 1.0
    np.testing.assert_allclose(nodes, 1.0 - nodes[::-1], atol=1e-15)
    np.testing.assert_allclose(weights, weights[::-1], atol=1e-15)
    for degree in range(2 * points - 2):
        assert abs(weights @ nodes ** degree - 1.0 / (degree + 1)) < 1e-14, degree
    degree = 2 * points - 2
    assert abs(weights @ nodes ** degree - 1.0 / (degree + 1)) > 1e-6


@pytest.mark.fast
def test_the_composition_from_order_4_meets_the_order_6_conditions():
    fractions = np.array(FROM_ORDER_4)
    assert math.isclose(fractions.sum(), 1.0, abs_tol=1e-15)
    np.testing.assert_array_equal(fractions, fractions[::-1])
    assert abs((fractions ** 5).sum()) < 1e-15


class NumpyStep:
    """The Galerkin step of `scene` by a numpy Newton on its SymPy residual (differenced
    Jacobian): slow, independent of code generation."""

    def __init__(self, scene, quadrature: int):
        scheme = galerkin.build(scene, quadrature)
        self.scheme = scheme
        self.residual = scheme.step_function(scheme.residual)
        self.next_state = scheme.step_function(scheme.next_state)
        self.flows = scheme.step_function([scheme.input_work, scheme.dissipated])
        arguments = list(scheme.state) + [scheme.dt]
        self.predictor = sp.lambdify(arguments, list(scheme.predictor))
        energy = scheme.state_function([scheme.energy])
        self.energy = lambda *x: energy(*x)[0]
        self.n = scene.n

    def solve(self, x, u, dt):
        z = np.array(self.predictor(*x, dt), float)
        for _ in range(40):
            r = np.array(self.residual(*z, *x, *u, dt), float)
            jacobian = np.empty((len(z), len(z)))
            for j in range(len(z)):
                dz = np.zeros(len(z))
                dz[j] = 1e-7 * max(1.0, abs(z[j]))
                jacobian[:, j] = (np.array(self.residual(*(z + dz), *x, *u, dt), float) - r) / dz[j]
            update = np.linalg.solve(jacobian, -r)
            z = z + update
            if np.abs(update).max() <= 1e-15 * max(1.0, np.abs(z).max()):
                break
        return z

    def step(self, x, dt, u=()):
        z = self.solve(x, u, dt)
        return np.array(self.next_state(*z, *x, *u, dt), float), \
            np.array(self.flows(*z, *x, *u, dt), float)

    def run(self, dt, t_end, u=()):
        x = np.concatenate([self.scheme.scene.initial_angles,
                            self.scheme.scene.initial_velocities]).astype(float)
        for _ in range(round(t_end / dt)):
            x, _ = self.step(x, dt, u)
        return x


@cache
def numpy_step(name: str, quadrature: int) -> NumpyStep:
    return NumpyStep(load(name), quadrature)


@pytest.mark.heavy
def test_the_step_is_symmetric():
    """Phi_-h(Phi_h(x)) = x: what makes the Suzuki composition of it of order 6."""
    stepper = numpy_step("three_link_multi", 3)
    x0 = np.array([0.7, 0.4, -0.2, 0.5, -1.0, 0.8])
    x1, _ = stepper.step(x0, 0.1)
    back, _ = stepper.step(x1, -0.1)
    assert np.abs(x1 - x0).max() > 0.01
    np.testing.assert_allclose(back, x0, atol=1e-12)


@pytest.mark.heavy
@pytest.mark.parametrize("name", ["three_link_mono", "three_link_multi"])
def test_the_step_alone_is_of_order_4_in_angles_and_rates(name):
    """Global error at t = 0.8 s against the same step at dt / 8: log2 of the ratio at dt
    0.2 and 0.1 within 4 +- 0.2, in the angles and in the rates."""
    stepper = numpy_step(name, 3)
    n, t_end = stepper.n, 0.8
    reference = stepper.run(0.0125, t_end)
    errors = [np.abs(stepper.run(dt, t_end) - reference) for dt in (0.2, 0.1)]
    for part in (slice(0, n), slice(n, 2 * n)):
        observed = math.log2(errors[0][part].max() / errors[1][part].max())
        assert abs(observed - 4.0) <= 0.2, (name, part, observed)


@pytest.mark.heavy
def test_the_energy_error_of_a_step_is_the_quadrature_s():
    """One step of 0.1 s: the energy change falls with the nodes (K = 2, 3, 5), to round-off
    at K = 5; the step's trajectory barely changes with K."""
    x0 = np.array([0.7, 0.4, -0.2, 0.5, -1.0, 0.8])
    changes, states = [], []
    for quadrature in (2, 3, 5):
        stepper = numpy_step("three_link_multi", quadrature)
        x1, _ = stepper.step(x0, 0.1)
        changes.append(abs(stepper.energy(*x1) - stepper.energy(*x0)))
        states.append(x1)
    assert changes[0] > 10 * changes[1] > 0
    assert changes[2] <= 1e-13 * abs(numpy_step("three_link_multi", 5).energy(*x0)) + 1e-14
    assert np.abs(states[1] - states[2]).max() < 1e-6


@pytest.mark.heavy
def test_the_energy_balance_holds_with_torques_and_damping():
    """four_link_actuated, K = 7, dt = 0.05 s: H_1 - H_0 = tau . (phi_1 - phi_0) - dissipated
    per step to round-off, dissipated > 0. (At K = 5 the rule's error is 1.4e-12 J in one of
    these steps, 3e-14 of H: the balance is exact but for the quadrature.)"""
    scene = load("four_link_actuated")
    stepper = NumpyStep(scene, 7)
    rng = np.random.default_rng(5)
    x = np.concatenate([scene.initial_angles, scene.initial_velocities]).astype(float)
    for _ in range(5):
        u = rng.uniform(-1.0, 1.0, len(scene.actuated_joints))
        x1, (work, dissipated) = stepper.step(x, 0.05, u)
        change = stepper.energy(*x1) - stepper.energy(*x)
        assert dissipated > 0
        assert abs(change - work + dissipated) <= 1e-12, (change, work, dissipated)
        x = x1


@pytest.mark.fast
def test_the_bench_names_k_at_order_6_even_without_springs():
    """The Galerkin rule integrates every term: K matters on a scene without springs too."""
    from chaingen.studies.bench.accuracy import order_label

    gravity = load("three_link_gravity")
    assert order_label(gravity, "es", 5, 6) == "es K=5 order 6"
    assert order_label(gravity, "es", 5, 4) == "es order 4"
