"""Method "es" for spatial scenes (issue 33, build 1): the director formulation and its
energy-momentum step (numpy: chaingen.symbolic.spatial_com_model; the generated scheme:
chaingen.symbolic.schemes.spatial_es; docs/model.md 4.8), against independent paths.

The pieces against derivatives and the joint-space dynamics of chaingen.spatial.dynamics
(itself checked against Pinocchio): the constraint Jacobian against central differences, the
springs' discrete gradient against V(q_1) - V(q_0), the kinetic energy of the constant mass
matrix against 1/2 qdot . M(q) qdot. The step: energy and constraints to round-off over 1000
steps of random conservative 3- and 5-link chains, the energy balance with torques and damping
per step; compiled, order 2 convergence to scipy's DOP853 on the joint-space equations of
motion (C qdot + g from Pinocchio's rnea) and to the spatial midpoint. The generated scheme,
built from its own SymPy expressions, against the numpy step: its residual vanishes at the
numpy step's root, its maps give the same state, energy, angles and rates, and the compiled
package runs the numpy trajectory.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_spatial_dynamics import random_scene
from test_spatial_midpoint import reference_run, wrapped

from chaingen.errors import UnsupportedSceneError
from chaingen.spatial import dynamics
from chaingen.symbolic import spatial_com_model as directors
from chaingen.symbolic.schemes import SPATIAL_BUILDERS, build_scheme

from helpers import require_tools


def random_state(scene, seed):
    """(angles, rates, q, v) of a random joint-space state of `scene`."""
    rng = np.random.default_rng(seed)
    angles, rates = rng.uniform(-1.0, 1.0, scene.n), rng.uniform(-1.0, 1.0, scene.n)
    model = directors.director_model(scene)
    q, v = directors.joint_space_start(model, angles, rates)
    return model, angles, rates, q, v


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 6))
def test_joint_space_start_is_on_the_constraints_and_reads_back(seed, n):
    """The start from joint angles and rates satisfies g = 0 and G v = 0, reads back the same
    angles and rates, and has the joint-space energies of chaingen.spatial.dynamics: the
    constant M of the directors gives 1/2 qdot . M(q) qdot."""
    scene = random_scene(seed, n, springs=True)
    model, angles, rates, q, v = random_state(scene, seed)
    assert np.abs(directors.constraints(model, q)).max() <= 1e-14
    assert np.abs(directors.constraint_jacobian(model, q) @ v).max() <= 1e-13
    np.testing.assert_allclose(directors.joint_angles(model, q), angles, rtol=0, atol=1e-14)
    np.testing.assert_allclose(directors.joint_rates(model, q, v), rates, rtol=0, atol=1e-13)
    kinetic = dynamics.kinetic_energy(scene, angles, rates)
    assert 0.5 * v @ model.mass_matrix @ v == pytest.approx(kinetic, rel=1e-12)
    assert directors.potential(model, q) == pytest.approx(
        dynamics.potential_energy(scene, angles), rel=1e-12, abs=1e-12)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 5))
def test_constraint_jacobian_and_discrete_gradient(seed, n):
    """Off the constraints, at random q: G against central differences of g (exact for a
    quadratic g but for round-off); the midpoint identity G(q_m)(q_1 - q_0) = g(q_1) - g(q_0);
    gradV~ . (q_1 - q_0) = V(q_1) - V(q_0), and gradV~(q, q) the gradient of V."""
    scene = random_scene(seed, n, springs=True)
    model = directors.director_model(scene)
    rng = np.random.default_rng(seed)
    q0, q1 = rng.normal(size=(2, 12 * n))
    h = 1e-6
    columns = [(directors.constraints(model, q0 + h * e) - directors.constraints(model, q0 - h * e))
               / (2 * h) for e in np.eye(12 * n)]
    np.testing.assert_allclose(directors.constraint_jacobian(model, q0), np.array(columns).T,
                               rtol=0, atol=1e-8)
    qm = (q0 + q1) / 2
    np.testing.assert_allclose(directors.constraint_jacobian(model, qm) @ (q1 - q0),
                               directors.constraints(model, q1) - directors.constraints(model, q0),
                               rtol=0, atol=1e-13)
    change = directors.potential(model, q1) - directors.potential(model, q0)
    scale = abs(directors.potential(model, q0)) + abs(directors.potential(model, q1))
    assert directors.discrete_gradient(model, q0, q1) @ (q1 - q0) == pytest.approx(
        change, rel=0, abs=1e-13 * scale)
    gradient = [(directors.potential(model, q0 + h * e) - directors.potential(model, q0 - h * e))
                / (2 * h) for e in np.eye(12 * n)]
    np.testing.assert_allclose(directors.discrete_gradient(model, q0, q0), gradient,
                               rtol=1e-6, atol=1e-6 * np.abs(gradient).max())


def test_torque_forces_do_the_work_of_the_joint_torques():
    """f(q, tau) . v = sum tau_i phidot_i(q, v) for any v, on the constraints or not."""
    scene = random_scene(5, 4, springs=True)
    model, _, rates, q, v = random_state(scene, 5)
    rng = np.random.default_rng(5)
    torques = rng.normal(size=4)
    assert directors.torque_forces(model, q, torques) @ v == pytest.approx(torques @ rates,
                                                                           rel=1e-13)
    other = rng.normal(size=12 * 4)
    assert directors.torque_forces(model, q, torques) @ other == pytest.approx(
        torques @ directors.joint_rates(model, q, other), rel=1e-13)


def run(model, q, v, dt, steps, inputs=None):
    """es steps from (q, v): the states and the steps' flows."""
    springs = directors.spring_maps(model)
    states, work, dissipated = [(q, v)], [], []
    guess = None
    for k in range(steps):
        step = directors.es_step(model, q, v, dt, () if inputs is None else inputs[k], springs,
                                 guess)
        q, v, guess = step.q, step.v, step.unknowns
        states.append((q, v))
        work.append(step.input_work)
        dissipated.append(step.dissipated)
    return states, np.array(work), np.array(dissipated)


@pytest.mark.heavy
@pytest.mark.parametrize("n, seed", [(3, 41), (5, 42)])
@pytest.mark.slow
def test_energy_and_constraints_to_round_off_over_1000_steps(n, seed):
    """A conservative random chain (gravity, springs routed over one to three joints, skew
    axes, full inertia tensors) at dt = 0.01 s: |H_k - H_0| <= 1e-12 of the energy's size and
    the constraint errors at round-off, while the motion is large."""
    scene = random_scene(seed, n, springs=True)
    model, angles, _, q, v = random_state(scene, seed)
    states, _, _ = run(model, q, v, 0.01, 1000)
    springs = directors.spring_maps(model)
    energies = np.array([directors.energy(model, q, v, springs) for q, v in states])
    size = 0.5 * v @ model.mass_matrix @ v + abs(directors.potential(model, q, springs))
    assert np.abs(energies - energies[0]).max() <= 1e-12 * size, (energies - energies[0])
    errors = [np.abs(directors.constraints(model, q)).max() for q, _ in states]
    assert max(errors) <= 1e-13, max(errors)
    moved = np.abs(wrapped(directors.joint_angles(model, states[-1][0]) - angles)).max()
    assert moved >= 0.1, moved


@pytest.mark.heavy
def test_balance_with_torques_and_damping_per_step():
    """Damped joints and random torques on three of four joints: every step's
    H_1 - H_0 = dt sum u_i phidot_i(m) - dt sum d_i phidot_i(m)^2 to round-off, with both
    flows far from zero."""
    plain = random_scene(51, 4, springs=True)
    damping = np.array([0.3, 0.0, 0.8, 0.2])
    scene = dataclasses.replace(plain, actuated=(1, 2, 4), links=tuple(
        dataclasses.replace(link, damping=float(d)) for link, d in zip(plain.links, damping)))
    model, _, _, q, v = random_state(scene, 51)
    inputs = np.random.default_rng(51).uniform(-2.0, 2.0, (200, 3))
    states, work, dissipated = run(model, q, v, 0.01, 200, inputs)
    springs = directors.spring_maps(model)
    energies = np.array([directors.energy(model, q, v, springs) for q, v in states])
    size = np.abs(energies).max()
    balance = np.diff(energies) - work + dissipated
    assert np.abs(balance).max() <= 1e-13 * size, np.abs(balance).max()
    assert dissipated.sum() >= 1e-3 * size and np.abs(work).sum() >= 1e-3 * size


def actuated_damped(seed, n):
    """(scene, u, angles, rates): a random chain with springs, damping on every joint and
    torques u on its first and last joints."""
    rng = np.random.default_rng(seed)
    plain = random_scene(seed, n, springs=True)
    actuated = tuple(sorted({1, n}))
    scene = dataclasses.replace(plain, actuated=actuated, links=tuple(
        dataclasses.replace(link, damping=float(d))
        for link, d in zip(plain.links, rng.uniform(0.0, 0.5, n))))
    return (scene, rng.uniform(-1.0, 1.0, len(actuated)), rng.uniform(-1.0, 1.0, n),
            rng.uniform(-1.0, 1.0, n))


@pytest.mark.compile
@pytest.mark.slow
def test_converges_at_order_2_to_dop853():
    """Random 3-link chain, springs, gravity, damping on every joint, torques on two: the
    compiled es's angle error at t = 1 s against DOP853 on M qddot = tau - d qdot - C qdot - g
    - dV_s/dq (Pinocchio's rnea) falls by 4 per halving of dt."""
    from chaingen.simulation import build_solver

    scene, u, angles, rates = actuated_damped(61, 3)
    torques = np.zeros(3)
    torques[[0, 2]] = u
    expected = reference_run(scene, angles, rates, torques, 1.0)
    solver = build_solver(scene, "es", sensitivities=False)
    errors = []
    for dt in (2e-3, 1e-3, 5e-4, 2.5e-4):
        steps = round(1.0 / dt)
        result = solver.simulate(angles, rates, dt=dt, n_steps=steps, every=steps,
                                 torques=np.tile(u, (steps, 1)))
        errors.append(np.abs(wrapped(result.phi[-1] - expected)).max())
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((3.8 <= ratios) & (ratios <= 4.2)), (errors, ratios)


@pytest.mark.compile
def test_composed_step_of_order_4_converges_to_dop853_in_angles_and_rates():
    """es composed to order 4 (Suzuki's 5 stages, docs/model.md 14) on a damped chain with
    springs (a tenth of random_scene's stiffness, as the spatial vi's order test): the error
    at t = 1 s against DOP853 falls by 2^4 per halving of dt, in the angles and in the rates
    (those of v projected onto the constraints' tangent space; the nodal v's own rates stay of
    order 2); the energy balance holds per step as at order 2."""
    from chaingen.simulation import build_solver

    plain = random_scene(51, 3, springs=True)
    scene = dataclasses.replace(plain, springs=tuple(
        dataclasses.replace(spring, stiffness=spring.stiffness / 10) for spring in plain.springs),
        links=tuple(dataclasses.replace(link, damping=0.1) for link in plain.links))
    rng = np.random.default_rng(51)
    q0, w0 = rng.uniform(-1.0, 1.0, 3), rng.uniform(-1.0, 1.0, 3)
    angles, rates = reference_run(scene, q0, w0, np.zeros(3), 1.0, with_rates=True)
    solver = build_solver(scene, "es", sensitivities=False, order=4)
    errors = []
    for dt in (1e-2, 5e-3):
        steps = round(1.0 / dt)
        result = solver.simulate(q0, w0, dt=dt, n_steps=steps)
        errors.append((np.abs(wrapped(result.phi[-1] - angles)).max(),
                       np.abs(result.omega[-1] - rates).max()))
        assert np.abs(result.balance_error).max() <= 1e-12 * np.abs(result.energy).max()
    ratios = np.array(errors[0]) / np.array(errors[1])
    assert np.all((0.7 * 16 <= ratios) & (ratios <= 1.3 * 16)), (errors, ratios)


@pytest.mark.compile
def test_adaptive_steps_keep_the_balance_and_meet_the_tolerance():
    """Adaptive es on a spatial chain (options rtol/atol, docs/model.md 15), damped and driven
    by constant torques: the step length varies, every step keeps the energy balance and the
    constraints to round-off, and the error at t = 1 s against DOP853 shrinks with the
    tolerance."""
    from chaingen.simulation import build_solver

    scene, u, angles, rates = actuated_damped(61, 3)
    torques = np.zeros(3)
    torques[[0, 2]] = u
    expected = reference_run(scene, angles, rates, torques, 1.0)
    solver = build_solver(scene, "es", sensitivities=False)
    errors = []
    for rtol in (1e-5, 1e-8):
        result = solver.simulate(angles, rates, dt=0.05, n_steps=20, options={
            "rtol": rtol, "atol": rtol}, torques=np.tile(u, (20, 1)))
        assert result.adaptive and result.accepted_steps > 20
        assert result.smallest_dt < result.largest_dt <= 0.05
        assert np.abs(result.balance_error).max() <= 1e-12 * np.abs(result.energy).max()
        assert np.abs(result.constraint_error).max() <= 1e-13
        errors.append(np.abs(wrapped(result.phi[-1] - expected)).max())
    assert errors[1] < errors[0] / 10 and errors[1] < 1e-5, errors


@pytest.mark.compile
def test_converges_to_the_spatial_midpoint():
    """The same chain by the compiled spatial es and midpoint (joint coordinates,
    Newton-Euler): two order 2 schemes of the same equations, so their difference at t = 1 s
    falls by 4 per halving of dt."""
    from chaingen.simulation import build_solver

    scene, u, angles, rates = actuated_damped(71, 3)
    solvers = [build_solver(scene, method, sensitivities=False) for method in ("midpoint", "es")]
    differences = []
    for dt in (1e-2, 5e-3, 2.5e-3, 1.25e-3):
        steps = round(1.0 / dt)
        midpoint, es = (solver.simulate(angles, rates, dt=dt, n_steps=steps, every=steps,
                                        torques=np.tile(u, (steps, 1))).phi[-1]
                        for solver in solvers)
        differences.append(np.abs(wrapped(es - midpoint)).max())
    ratios = np.array(differences[:-1]) / np.array(differences[1:])
    assert np.all((3.6 <= ratios) & (ratios <= 4.4)), (differences, ratios)


# -- the generated scheme -------------------------------------------------------------------

def reduced_step(scheme, q, v, u, dt):
    """The generated (reduced) scheme's step by Newton's method in numpy from its predictor,
    dF/dw by central differences: (w, next state and flows)."""
    n = scheme.scene.n
    residual = scheme.step_function(list(scheme.residual))
    finish = scheme.step_function(list(scheme.next_state) + [scheme.input_work,
                                                             scheme.dissipated])
    predict = scheme.state_function(list(scheme.predictor), [scheme.dt])
    w = np.array(predict(*q, *v, dt), dtype=float).ravel()

    def F(w):
        return np.array(residual(*w, *q, *v, *u, dt), dtype=float).ravel()

    for _ in range(30):
        h = 1e-7 * max(1e-3, np.abs(w).max())
        jacobian = np.array([(F(w + h * e) - F(w - h * e)) / (2 * h) for e in np.eye(n)]).T
        update = np.linalg.solve(jacobian, -F(w))
        w = w + update
        if np.abs(update).max() <= 1e-15 * np.abs(w).max():
            break
    return w, np.array(finish(*w, *q, *v, *u, dt), dtype=float).ravel()


@pytest.mark.heavy    # SymPy on chains of up to 6-7 links: 4-5 s, out of the fast tier
@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 3))
def test_scheme_is_the_numpy_step(seed, n):
    """An actuated, damped random chain: the reduced scheme (n turns, the momentum balance
    projected on the joint twists) and the numpy step on the full saddle point (dv and the
    constraint impulses, 23n unknowns) are the same step: the same next state and flows to
    round-off, and the reduced residual vanishes at the numpy step's turns. Its maps give the
    numpy start, energy, angles, rates and constraint errors, at the start and after the
    step."""
    scene, u, angles, rates = actuated_damped(seed, n)
    scheme = build_scheme(scene, "es")
    assert scheme.unknowns.shape[0] == n
    model = directors.director_model(scene)
    q, v = directors.joint_space_start(model, angles, rates)
    start = np.array(scheme.initial_function()(*angles, *rates), dtype=float).ravel()
    np.testing.assert_allclose(start, np.concatenate([q, v]), rtol=0, atol=1e-14)
    dt = 0.01
    step = directors.es_step(model, q, v, dt, u)
    w, out = reduced_step(scheme, q, v, u, dt)
    # v_1 = 2 (q_1 - q_0) / dt - v_0: round-off of q over dt
    np.testing.assert_allclose(out[:12 * n], step.q, rtol=0, atol=1e-14)
    np.testing.assert_allclose(out[12 * n:-2], step.v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out[-2:], [step.input_work, step.dissipated], rtol=1e-11,
                               atol=1e-16)
    turns = wrapped(directors.joint_angles(model, step.q) - directors.joint_angles(model, q))
    np.testing.assert_allclose(w, 2 * np.tan(turns / 2), rtol=0, atol=1e-13)
    state = scheme.state_function([scheme.energy, *scheme.joint_angles,
                                   *scheme.joint_velocities, *scheme.constraint_residuals])
    for q_, v_ in ((q, v), (step.q, step.v)):
        values = np.array(state(*q_, *v_), dtype=float).ravel()
        assert values[0] == pytest.approx(directors.energy(model, q_, v_), rel=1e-13)
        np.testing.assert_allclose(values[1:n + 1], directors.joint_angles(model, q_), atol=1e-14)
        np.testing.assert_allclose(values[n + 1:2 * n + 1], directors.joint_rates(model, q_, v_),
                                   atol=1e-13)
        np.testing.assert_allclose(values[2 * n + 1:], directors.constraints(model, q_),
                                   atol=1e-14)


@pytest.mark.heavy
@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 6))
def test_turns_keep_the_constraints_and_the_twists_span_their_null_space(seed, n):
    """The two halves of the reduction, for random chains, states and turns up to 3 rad:
    q_1 = q_0 + dq(q_0, w) keeps g (g(q_1) at round-off, by construction, whatever w), and
    the residual's projection P(q_m)^T annihilates every constraint force G(q_m)^T mu (the
    joint twists span the null space of G(q_m)), so the impulses drop out; P(q_m)^T of a
    generalized force f is sum_i f . xi_j with xi_j the joint twists, checked against
    f . (dq/dw_j) at w = 0 (the twist turns the same links about the same axis)."""
    import sympy as sp

    from chaingen.symbolic.recursion import Definitions
    from chaingen.symbolic.schemes import spatial_es, spatial_null_space

    scene = random_scene(seed, n, springs=True)
    model, _, _, q0, _ = random_state(scene, seed)
    rng = np.random.default_rng(seed)
    w = rng.uniform(-3.0, 3.0, n)
    q_symbols = sp.symbols(f"q0:{12 * n}", real=True)
    w_symbols = sp.symbols(f"w0:{n}", real=True)
    f_symbols = sp.symbols(f"f0:{12 * n}", real=True)
    defs = Definitions("t_")
    dq = spatial_null_space.turned_frames(scene, q_symbols, w_symbols, defs)
    qm = [q + d / 2 for q, d in zip(q_symbols, dq)]
    axes, _ = spatial_es.joint_rates(scene, qm, [sp.Integer(0)] * (12 * n), defs, "m")
    moments = spatial_null_space.joint_moments(scene, qm, f_symbols, axes, defs)
    inputs = [*q_symbols, *w_symbols, *f_symbols]
    evaluate = sp.lambdify(inputs, list(dq) + moments, modules="numpy",
                           cse=lambda e: (list(defs.items) + sp.cse(e)[0], sp.cse(e)[1]))

    def at(w, f):
        out = np.array(evaluate(*q0, *w, *f), dtype=float).ravel()
        return out[:12 * n], out[12 * n:]

    dq_value, _ = at(w, np.zeros(12 * n))
    q1 = q0 + dq_value
    assert np.abs(directors.constraints(model, q1)).max() <= 1e-14
    assert np.abs(wrapped(directors.joint_angles(model, q1) - directors.joint_angles(model, q0)
                          - 4 * np.arctan(w / 2) / 2)).max() <= 1e-12
    qm = (q0 + q1) / 2
    mu = rng.normal(size=11 * n)
    _, projected = at(w, directors.constraint_jacobian(model, qm).T @ mu)
    assert np.abs(projected).max() <= 1e-13 * np.abs(mu).max()
    f = rng.normal(size=12 * n)
    h = 1e-6
    twists = np.array([(at(h * e, f)[0] - at(-h * e, f)[0]) / (2 * h) for e in np.eye(n)])
    _, at_start = at(np.zeros(n), f)
    np.testing.assert_allclose(at_start, twists @ f, rtol=1e-8, atol=1e-8 * np.abs(f).max())


@pytest.mark.heavy  # SymPy on up to six links: tens of seconds, too slow for the fast tier
@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 6))
@pytest.mark.slow
def test_newton_matrix_is_the_mass_matrix_at_rest_and_near_dF_dw(seed, n):
    """Newton's matrix A (spatial_null_space.newton_matrix, the composite rigid bodies with the
    mid-point and end configurations, and the damping): at w = 0 it is 2/dt times the
    joint-space mass matrix of chaingen.spatial.dynamics (itself checked against Pinocchio)
    plus the damping d_j on the diagonal; at the step's root at
    dt = 1 ms its chord contracts fast, |eig(1 - A^-1 dF/dw)| <= 0.05 (dF/dw by central
    differences)."""
    scene, u, angles, rates = actuated_damped(seed, n)
    scheme = build_scheme(scene, "es")
    model = directors.director_model(scene)
    q, v = directors.joint_space_start(model, angles, rates)
    dt = 1e-3
    matrix = scheme.step_function(list(scheme.newton_matrix))
    residual = scheme.step_function(list(scheme.residual))

    def A(w):
        return np.array(matrix(*w, *q, *v, *u, dt), dtype=float).reshape(n, n)

    damping = np.array([link.damping for link in scene.links])
    expected = dynamics.mass_matrix(scene, angles) + dt / 2 * np.diag(damping)
    np.testing.assert_allclose(A(np.zeros(n)) * dt / 2, expected, rtol=0,
                               atol=1e-12 * np.abs(expected).max())
    w, _ = reduced_step(scheme, q, v, u, dt)

    def F(w):
        return np.array(residual(*w, *q, *v, *u, dt), dtype=float).ravel()

    h = 1e-7 * max(1e-3, np.abs(w).max())
    jacobian = np.array([(F(w + h * e) - F(w - h * e)) / (2 * h) for e in np.eye(n)]).T
    rate = np.abs(np.linalg.eigvals(np.eye(n) - np.linalg.solve(A(w), jacobian))).max()
    assert rate <= 0.05, rate


def test_order_4_composed_order_6_the_galerkin_step():
    """Order 4 composes the step (docs/model.md 14); order 6, where a composition of it
    stalls at 4 as the planar es's does, is the k = 1 Galerkin step in joint angles composed
    from order 4 (tests/test_spatial_galerkin.py); the builder names the orders it takes."""
    scene = random_scene(1, 2)
    composed = build_scheme(scene, "es", order=4)
    assert len(composed.metadata.composition) == 5 and composed.maps.state.shape == (48, 1)
    galerkin = build_scheme(scene, "es", order=6)
    assert galerkin.step.unknowns.shape == (8, 1) and galerkin.maps.state.shape == (4, 1)
    with pytest.raises(UnsupportedSceneError, match="order 3: es for a spatial scene .* "
                                                    "takes orders 2, 4, 6"):
        SPATIAL_BUILDERS["es"](scene, 3, 3)


@pytest.mark.compile
@pytest.mark.parametrize("n, seed", [(3, 81), (5, 82)])
def test_compiled_es_conserves_energy_and_runs_the_numpy_trajectory(n, seed):
    """build_solver(scene, "es"): a conservative random chain over 1000 steps of 0.01 s keeps
    its energy to 1e-12 relative and its constraints to round-off; over the first 50 steps
    each compiled step from the numpy step's start gives its end to round-off (1e-13 rad, and
    1e-13 of the state). Step by step: these chains are chaotic at dt = 10 ms, a relative
    change of 1e-16 in v grows to 1.2e-13 rad in 50 numpy steps (3 links), so two correct
    implementations part by some 1e-12 rad there by round-off alone."""
    from chaingen.simulation import build_solver

    scene = random_scene(seed, n, springs=True)
    model, angles, rates, q, v = random_state(scene, seed)
    solver = build_solver(scene, "es", sensitivities=False)
    result = solver.simulate(angles, rates, dt=0.01, n_steps=1000)
    size = 0.5 * v @ model.mass_matrix @ v + abs(directors.potential(model, q))
    assert result.energy[0] == pytest.approx(directors.energy(model, q, v), rel=1e-14)
    assert np.abs(result.energy - result.energy[0]).max() <= 1e-12 * size
    assert np.abs(result.constraint_error).max() <= 1e-13
    assert np.abs(wrapped(result.phi[-1] - angles)).max() >= 0.1
    states, _, _ = run(model, q, v, 0.01, 50)
    for (q0, v0), (q1, v1) in zip(states, states[1:]):
        x1 = solver.step(np.concatenate([q0, v0]), None, 0.01).x1
        assert np.abs(wrapped(directors.joint_angles(model, x1[:12 * n])
                              - directors.joint_angles(model, q1))).max() <= 1e-13
        np.testing.assert_allclose(x1, np.concatenate([q1, v1]), rtol=0,
                                   atol=1e-13 * np.abs(np.concatenate([q1, v1])).max())


@pytest.mark.compile
def test_compiled_balance_with_torques_and_damping():
    """The package's flows and balance: H_k - H_0 - work + dissipated at round-off for random
    torques on three of four damped joints, with both flows far from zero."""
    from chaingen.simulation import build_solver

    plain = random_scene(91, 4, springs=True)
    damping = np.array([0.3, 0.0, 0.8, 0.2])
    scene = dataclasses.replace(plain, actuated=(1, 2, 4), links=tuple(
        dataclasses.replace(link, damping=float(d)) for link, d in zip(plain.links, damping)))
    _, angles, rates, _, _ = random_state(scene, 91)
    torques = np.random.default_rng(91).uniform(-2.0, 2.0, (500, 3))
    result = build_solver(scene, "es", sensitivities=False).simulate(
        angles, rates, dt=0.01, n_steps=500, torques=torques)
    size = np.abs(result.energy).max()
    assert np.abs(result.balance_error).max() <= 1e-12 * size
    assert result.dissipated[-1] >= 1e-3 * size and abs(result.input_work[-1]) > 0.0


@pytest.mark.compile
def test_sensitivities_and_generated_functions_pass_the_check():
    """chaingen check's comparisons on an actuated spatial scene: the residual Jacobian and
    the step sensitivities against central differences, every generated function against the
    scheme's SymPy expressions."""
    from chaingen.simulation import build_solver
    from chaingen.studies.check import check_solver

    scene, u, angles, rates = actuated_damped(101, 3)
    solver = build_solver(scene, "es", sensitivities=True)
    report = check_solver(build_scheme(scene, "es"), solver, samples=3, dt=0.01)
    assert {row.quantity for row in report.rows} >= {
        "residual Jacobian", "d s1 / d s0", "d s1 / d u", "residual", "energy", "next state"}
    # The check's reference Newton stops at the round-off floor (its updates near 5e-14 |z| on
    # this 23n saddle point, the residual at 1e-15), where an absolute 1e-14 |z| left it without
    # a reference for "next state" before.
    assert report.passed, report.table()
    assert dict((row.quantity, row.worst) for row in report.rows)["next state"] <= 1e-12
    model = directors.director_model(scene)
    q, v = directors.joint_space_start(model, angles, rates)
    step = directors.es_step(model, q, v, 0.01, u)
    x1 = solver.step(np.concatenate([q, v]), u, 0.01).x1
    np.testing.assert_allclose(x1, np.concatenate([step.q, step.v]), rtol=0, atol=1e-13)


@pytest.mark.tools
@pytest.mark.parametrize("actuated", [(), (1, 3)])
@pytest.mark.slow
def test_spatial_es_example_is_clean_under_valgrind_and_the_sanitizers(tmp_path, actuated):
    """The es package of a spatial chain as a user gets it (free motion, and an actuated,
    damped chain): its example program, compiled with the strict flags, runs clean under
    memcheck and under ASan/UBSan."""
    require_tools("gcc", "valgrind")
    import json
    import subprocess

    from chaingen.generate.package import generate_package, write_package
    from chaingen.runtime import contract

    plain = random_scene(111, 3, springs=True)
    scene = dataclasses.replace(plain, name="spatial-es-example", actuated=actuated,
                                links=tuple(dataclasses.replace(link, damping=0.2)
                                            for link in plain.links))
    package = write_package(generate_package(scene, "es", 3, sensitivities=False),
                            tmp_path / "package")
    sources = [package / name for name in json.loads((package / "chaingen.json").read_text())
               ["sources"]]
    for name, flags, runner in (
            ("memcheck", ["-g", "-O1"], ["valgrind", "--error-exitcode=99",
                                         "--track-origins=yes", "--leak-check=full"]),
            ("sanitized", ["-g", "-fsanitize=address,undefined", "-fno-omit-frame-pointer",
                           "-fno-sanitize-recover=all"], [])):
        binary = tmp_path / name
        built = subprocess.run(["gcc", *flags, *contract.STRICT_FLAGS, f"-I{package}",
                                *map(str, sources), str(package / "example.c"), "-lm", "-o",
                                str(binary)], capture_output=True, text=True, timeout=300)
        assert built.returncode == 0, built.stderr
        run = subprocess.run([*runner, str(binary), "0.2"], capture_output=True, text=True,
                             timeout=600)
        assert run.returncode == 0, run.stdout + run.stderr
        if runner:
            assert "ERROR SUMMARY: 0 errors" in run.stderr, run.stderr
        assert ("final tracking error" in run.stdout) == bool(actuated), run.stdout


@pytest.mark.compile
def test_a_root_that_turns_a_link_half_round_is_refused_and_split():
    """spatial_three_link at dt = 0.05 s: its tenth step from the start turns link 3 by 180
    degrees, where P(q_m) no longer spans the null space of G(q_m), and the projected residual
    has a root that is not a root of the step: it gained 47.8 J (H = 24.6 J), and the run
    failed with NaN at step 29 after more such steps. The energy check (ENERGY_TOL) refuses it
    and splits it: the run completes 2 s with the balance at round-off."""
    from chaingen.simulation import build_solver
    from chaingen.spatial import load_spatial_scene

    from helpers import scene_path

    scene = load_spatial_scene(scene_path("spatial_three_link"))
    solver = build_solver(scene, "es", sensitivities=False)
    x = solver.initial_state(scene.initial_angles, scene.initial_velocities)
    for _ in range(9):
        x = solver.step(x, dt=0.05).x1
    unchecked = solver.step(x, dt=0.05, options={"energy_tol": 0.0})
    balance = (solver.outputs(unchecked.x1)[2] - solver.outputs(x)[2]
               - unchecked.input_work + unchecked.dissipated)
    assert abs(balance) > 1.0
    run = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.05, n_steps=40)
    assert run.split_steps >= 1
    assert np.max(np.abs(run.balance_error)) <= 1e-12 * np.max(np.abs(run.energy))


def test_k_plays_no_role_in_the_spatial_es_below_order_6():
    """The spatial es takes the springs' exact discrete gradient by the chain rule up to order
    4 (no quadrature: its manifest says null), so its solver spec, label and cache key carry no
    K there (they said K = 3: an order study given such a solver refused it as 'quadrature
    None, not 3', and K = 3 and 5 were two builds of one package), and its gradient is the
    chain rule's whatever is asked (the manifest's); at order 6 the Galerkin step's Lobatto
    rule takes K, and the planar es averages its springs by K points."""
    from chaingen.generate.key import solver_key
    from chaingen.scene import load_reference_scene
    from chaingen.scene.labels import scheme_label
    from chaingen.scene.shipped import scene_file
    from chaingen.scene.solver_spec import SolverSpec
    from chaingen.spatial import load_spatial_scene

    spatial = load_spatial_scene(scene_file("spatial_three_link"))
    assert spatial.springs
    for order in (2, 4):
        spec = SolverSpec(spatial, "es", 3, order=order, sensitivities=False)
        assert spec.quadrature_used is None
        assert "K" not in scheme_label("es", spec.quadrature_used, order)
        assert (solver_key(spatial, "es", 3, sensitivities=False, order=order)
                == solver_key(spatial, "es", 5, sensitivities=False, order=order))
        for asked in ("exact", "quadrature", "chain"):
            assert SolverSpec(spatial, "es", 3, order=order, sensitivities=False,
                              gradient=asked).gradient_used == "chain"
    assert SolverSpec(spatial, "es", 3, order=6, sensitivities=False).quadrature_used == 3
    planar = load_reference_scene("three_link_mono")
    assert SolverSpec(planar, "es", 3, sensitivities=False).quadrature_used == 3
    assert SolverSpec(planar, "es", 3, sensitivities=False).gradient_used == "exact"


@pytest.mark.compile
def test_an_order_study_takes_a_built_spatial_es_solver():
    """Given the spatial es solver build_solver makes (manifest: quadrature null, gradient
    "chain"), the order study runs on it; it refused it as 'quadrature None, not 3' while the
    spec said K = 3 (and would have as 'gradient chain, not exact' after that)."""
    from chaingen.scene.shipped import scene_file
    from chaingen.simulation import build_solver
    from chaingen.spatial import load_spatial_scene
    from chaingen.studies.order import order_study

    scene = load_spatial_scene(scene_file("spatial_three_link"))
    solver = build_solver(scene, "es", sensitivities=False)
    study = order_study(scene, "es", 3, solver=solver, t_end=0.2)
    assert study.quadrature is None and study.gradient == "chain"
