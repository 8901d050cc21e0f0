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
    Jacobian): slow, independent of code generation. build: the planar step's builder, or
    the spatial one's (spatial_galerkin.build)."""

    def __init__(self, scene, quadrature: int, exact_energy: bool = True, build=galerkin.build):
        scheme = build(scene, quadrature, exact_energy=exact_energy)
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
def numpy_step(name: str, quadrature: int, exact_energy: bool = True) -> NumpyStep:
    return NumpyStep(load(name), quadrature, exact_energy)


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
def test_the_rule_s_energy_error_falls_with_k_and_the_correction_removes_it():
    """One step of 0.1 s on three_link_multi. The rule alone (exact_energy=False): the energy
    change falls with the nodes (K = 2, 3, 5), to round-off at K = 5. Corrected (the default,
    model.md 16): round-off at every K, and the trajectory moves by no more than the rule's
    error (the correction is of its size)."""
    x0 = np.array([0.7, 0.4, -0.2, 0.5, -1.0, 0.8])
    energy = numpy_step("three_link_multi", 5).energy
    scale = abs(energy(*x0))
    changes, states = [], []
    for quadrature in (2, 3, 5):
        stepper = numpy_step("three_link_multi", quadrature, False)
        x1, _ = stepper.step(x0, 0.1)
        changes.append(abs(energy(*x1) - energy(*x0)))
        states.append(x1)
        corrected, _ = numpy_step("three_link_multi", quadrature).step(x0, 0.1)
        assert abs(energy(*corrected) - energy(*x0)) <= 1e-14 * scale, quadrature
        assert np.abs(corrected - x1).max() <= 1e-6, quadrature
    assert changes[0] > 10 * changes[1] > 0
    assert changes[0] > 1e-9 * scale
    assert changes[2] <= 1e-13 * scale + 1e-14
    assert np.abs(states[1] - states[2]).max() < 1e-6


@pytest.mark.heavy
def test_the_energy_balance_holds_with_torques_and_damping():
    """four_link_actuated, K = 3 (the default), dt = 0.05 s: H_1 - H_0 = tau . (phi_1 - phi_0)
    - dissipated per step to round-off, dissipated > 0. The rule alone misses it by 1e-7 of H
    in these steps: the correction is what closes it, with the sign and scale of model.md 16."""
    scene = load("four_link_actuated")
    rng = np.random.default_rng(5)
    x = np.concatenate([scene.initial_angles, scene.initial_velocities]).astype(float)
    corrected, alone = NumpyStep(scene, 3), NumpyStep(scene, 3, exact_energy=False)
    scale = abs(corrected.energy(*x))
    for _ in range(5):
        u = rng.uniform(-1.0, 1.0, len(scene.actuated_joints))
        defects = []
        for stepper in (corrected, alone):
            x1, (work, dissipated) = stepper.step(x, 0.05, u)
            assert dissipated > 0
            defects.append(stepper.energy(*x1) - stepper.energy(*x) - work + dissipated)
        assert abs(defects[0]) <= 1e-14 * scale, defects
        assert abs(defects[1]) >= 1e-10 * scale, defects
        x, _ = corrected.step(x, 0.05, u)


@pytest.mark.heavy
def test_the_correction_fades_out_below_delta():
    """Near rest (rates of 1e-6 rad/s), steps of |phi_1 - phi_0| far below delta = 5.8e-3 rad
    (K = 3): the correction is e |dphi| / delta^2, and the step is the rule's to round-off.
    Divided by |dphi|^2 instead, the round-off of H_1 - H_0 (eps H) would move it by about
    eps H / |w| (model.md 16). Fast steps are corrected."""
    x0 = np.array([0.7, 0.4, -0.2, 1e-6, -1e-6, 1e-6])
    corrected = numpy_step("three_link_multi", 3)
    alone = numpy_step("three_link_multi", 3, False)
    for dt in (0.001, 0.01):
        assert np.abs(corrected.step(x0, dt)[0] - alone.step(x0, dt)[0]).max() <= 1e-15
    fast = np.array([0.7, 0.4, -0.2, 0.5, -1.0, 0.8])
    assert np.abs(corrected.step(fast, 0.1)[0] - alone.step(fast, 0.1)[0]).max() >= 1e-12


@pytest.mark.fast
def test_the_bench_names_k_at_order_6_even_without_springs():
    """The Galerkin rule integrates every term: K matters on a scene without springs too."""
    from chaingen.studies.bench.accuracy import order_label

    gravity = load("three_link_gravity")
    assert order_label(gravity, "es", 5, 6) == "es K=5 order 6"
    assert order_label(gravity, "es", 5, 4) == "es order 4"
